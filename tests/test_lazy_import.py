"""core/net/lazy_import.py: a library imported without its optional parts, in threads."""

from __future__ import annotations

import sys
import threading
import time

import pytest

from rosnet_tui.core.net.lazy_import import import_without


@pytest.fixture
def libs(tmp_path, monkeypatch):
    """Two slow libraries (0.6 s to import each) and an optional module one of them tries."""
    for name in ("slow_lib_a", "slow_lib_b"):
        (tmp_path / f"{name}.py").write_text(
            "import time\ntime.sleep(0.6)\n"
            "try:\n    import optional_part\n    HAS_OPTIONAL = True\n"
            "except ImportError:\n    HAS_OPTIONAL = False\n")
    (tmp_path / "optional_part.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    for name in ("slow_lib_a", "slow_lib_b", "optional_part"):
        sys.modules.pop(name, None)


def test_the_held_module_is_off_during_the_import_and_back_after(libs):
    mod = import_without("slow_lib_a", "optional_part")
    assert mod.HAS_OPTIONAL is False
    assert "optional_part" not in sys.modules
    import optional_part  # noqa: F401 - importable again as usual

    assert import_without("slow_lib_a", "optional_part") is mod     # once only


def test_one_librarys_import_does_not_wait_for_anothers(libs):
    """The round imports paramiko (the SSH login) and requests (the HTTP checks) in two threads:
    the login waited for the whole of requests' import behind one lock."""
    took: dict[str, float] = {}

    def imp(name: str) -> None:
        t0 = time.monotonic()
        import_without(name, "optional_part")
        took[name] = time.monotonic() - t0

    threads = [threading.Thread(target=imp, args=(n,)) for n in ("slow_lib_a", "slow_lib_b")]
    t0 = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert sorted(took) == ["slow_lib_a", "slow_lib_b"]
    assert time.monotonic() - t0 < 1.1, took            # side by side: 0.6 s, not 1.2 s


def test_a_library_being_imported_is_waited_for_not_imported_twice(libs):
    got: list[object] = []
    first = threading.Thread(target=lambda: got.append(import_without("slow_lib_a")))
    first.start()
    time.sleep(0.2)                                     # the first import is under way
    got.append(import_without("slow_lib_a"))
    first.join(10)
    assert len(got) == 2 and got[0] is got[1]
    assert hasattr(got[1], "HAS_OPTIONAL")              # whole, not half-imported


def test_a_quieted_warning_stays_quiet_while_another_library_is_imported(tmp_path, monkeypatch):
    """requests' warning about the held character detector reached stderr in the lab: paramiko's
    import, side by side in another thread, left its ``catch_warnings`` while requests was still
    importing and put back the filters it had saved, without requests' quieting one."""
    (tmp_path / "quick_lib.py").write_text("import time\ntime.sleep(0.3)\n")
    (tmp_path / "warn_lib.py").write_text(
        "import time, warnings\ntime.sleep(0.8)\n"
        "try:\n    import warn_optional\nexcept ImportError:\n"
        "    warnings.warn('no warn_optional here, going on without it')\n")
    (tmp_path / "warn_optional.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    shown: list[str] = []
    monkeypatch.setattr("warnings.showwarning", lambda msg, *a, **k: shown.append(str(msg)))
    first = threading.Thread(target=import_without, args=("quick_lib", "quick_optional"))
    second = threading.Thread(target=import_without, args=("warn_lib", "warn_optional"),
                              kwargs={"quiet": "no warn_optional here"})
    try:
        first.start()
        deadline = time.monotonic() + 5     # the first import under way, then the second's
        while "quick_lib" not in sys.modules and time.monotonic() < deadline:
            time.sleep(0.005)
        second.start()
        first.join(5)
        second.join(5)
        assert "warn_lib" in sys.modules and "quick_lib" in sys.modules
    finally:
        for name in ("quick_lib", "warn_lib", "warn_optional"):
            sys.modules.pop(name, None)
    assert shown == []
