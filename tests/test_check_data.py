"""The declared data of the checks (rosnet_tui/core/checks/data/): the `check --json` contract.

Every registered check id has a declaration and every declaration a check; each declared key is
documented; docs/COMMANDS.md's table of the checks lists exactly the declared top-level keys;
producers report no undeclared key (here for every check's early branches, with real sockets on
loopback; the other check tests run under ROSNET_TUI_STRICT_DATA=1, where run_check refuses such
a key).
"""

from __future__ import annotations

import ast
import asyncio
import re
import typing
from pathlib import Path

import pytest

from rosnet_tui.core.checks import (
    CheckContext,
    CheckSpec,
    checks_for,
    data,
    run_check,
)
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import (
    Peer,
    ProbeSettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.options import SshOptions
from tests.builders import free_port

ROOT = Path(__file__).resolve().parent.parent
DATA_DIR = ROOT / "rosnet_tui" / "core" / "checks" / "data"


def _nested(tp: typing.Any) -> list[type]:
    """The TypedDicts inside a declared type (directly, in lists, as dict values, in unions)."""
    if typing.is_typeddict(tp):
        return [tp]
    return [t for a in typing.get_args(tp) for t in _nested(a)]


def _all_declarations() -> set[type]:
    seen: set[type] = set()
    todo = list(data.DATA.values())
    while todo:
        td = todo.pop()
        if td in seen:
            continue
        seen.add(td)
        for tp in typing.get_type_hints(td).values():
            todo.extend(_nested(tp))
    return seen


# --------------------------------------------------------------------------- ids
def test_every_registered_check_has_a_declaration_and_every_declaration_a_check():
    ids = [c.id for c in checks_for()]
    assert len(ids) == 32  # issue 22: security.ssh_auth, security.outsider, linux.firewall; 30: relay.router, relay.tunnel; 31: ros2.link, ros.link
    assert sorted(ids) == sorted(data.DATA)


def test_declarations_are_optional_key_typeddicts_that_resolve():
    for td in _all_declarations():
        assert typing.is_typeddict(td), td
        assert not td.__required_keys__, f"{td.__name__}: a check sets only what it has evidence for"
        hints = typing.get_type_hints(td)  # every annotation resolves
        assert hints, td


def test_every_declared_key_has_a_comment_saying_what_it_holds():
    """The comment on each key is its documentation (the `check --json` contract)."""
    names = {td.__name__ for td in _all_declarations()}
    found: set[str] = set()
    for path in sorted(DATA_DIR.glob("*.py")):
        lines = path.read_text().splitlines()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef) and node.name in names:
                found.add(node.name)
                for item in node.body:
                    if isinstance(item, ast.AnnAssign):
                        line = lines[item.lineno - 1]
                        assert "#" in line, f"{node.name}: no comment on {line.strip()!r}"
            # Functional syntax (for keys like "from"): Name = TypedDict("Name", {...}, ...)
            if (isinstance(node, ast.Call) and getattr(node.func, "id", "") == "TypedDict"
                    and isinstance(node.args[0], ast.Constant) and node.args[0].value in names):
                found.add(node.args[0].value)
                for key in node.args[1].keys:
                    line = lines[key.lineno - 1]
                    assert "#" in line, f"{node.args[0].value}: no comment on {line.strip()!r}"
    assert found == names


# --------------------------------------------------------------------------- docs/COMMANDS.md
def readme_table() -> dict[str, list[str]]:
    """docs/COMMANDS.md's table of the checks: check id -> the keys of its `data` column, in
    order."""
    text = (ROOT / "docs" / "COMMANDS.md").read_text()
    section = text[text.index("## The checks"):]
    section = re.split(r"\n#", section[1:], maxsplit=1)[0]
    rows = [ln for ln in section.splitlines() if ln.startswith("| `")]
    out: dict[str, list[str]] = {}
    for row in rows:
        cells = [c.strip() for c in row.strip().strip("|").split(" | ")]
        keys = re.findall(r"`([^`]+)`", cells[-1])
        for cid in re.findall(r"`([a-z0-9]+\.[a-z_]+)`", cells[0]):
            assert cid not in out, f"{cid} twice in docs/COMMANDS.md's table"
            out[cid] = keys
    return out


def expected_cell(check_id: str) -> str:
    return ", ".join(f"`{k}`" for k in typing.get_type_hints(data.DATA[check_id]))


def test_readme_table_lists_exactly_the_declared_top_level_keys():
    table = readme_table()
    assert sorted(table) == sorted(data.DATA), "docs/COMMANDS.md's table of the checks lists other ids"
    for cid, keys in table.items():
        declared = list(typing.get_type_hints(data.DATA[cid]))
        assert keys == declared, (f"docs/COMMANDS.md's data column for {cid} drifted from checks/data/; "
                                  f"it should read: {expected_cell(cid)}")
        assert set(keys) == data.declared_keys(cid)


# --------------------------------------------------------------------------- producers
def _ctx(tmp_path: Path, settings: Settings, timeout: float = 1.0) -> CheckContext:
    rc = tmp_path / "bashrc"
    rc.write_text("")
    paths = Paths(state_dir=tmp_path / "state", hosts_path=tmp_path / "hosts", bashrc_path=rc)
    return CheckContext(settings=settings, timeout_s=timeout, paths=paths, upnp=False,
                        ssh_options=SshOptions(ssh_agent=False, ssh_dir=tmp_path / "no-ssh"))


async def _run_all(ctx: CheckContext) -> dict:
    specs = checks_for()
    results = await asyncio.gather(*(run_check(s, ctx) for s in specs))
    return {r.id: r for r in results}


async def test_every_check_reports_only_declared_keys_when_there_is_nothing_to_check(tmp_path):
    """Empty settings: each check's skip or early-failure branch, nothing leaves the machine."""
    s = Settings(probe=ProbeSettings(port=free_port(), public_ip_urls=[], port_check_url=""))
    got = await _run_all(_ctx(tmp_path, s))
    assert len(got) == 32
    for cid, r in got.items():
        assert not r.summary.startswith("the check failed unexpectedly"), (cid, r.summary)
        assert data.undeclared(cid, r.data) == [], (cid, r.data)


async def test_every_check_reports_only_declared_keys_against_dead_loopback_services(tmp_path):
    """Settings that name a master, a peer and services, all on loopback ports nobody serves."""
    dead = free_port()
    s = Settings(this=ThisComponent(name="localhost", local_ip="127.0.0.1", role="master"),
                 peers=[Peer(name="localhost", local_ip="127.0.0.1", public_ip="127.0.0.1",
                             ssh_user="nobody", ssh_port=dead)],
                 probe=ProbeSettings(port=free_port(),
                                     public_ip_urls=[f"http://127.0.0.1:{dead}/ip"],
                                     port_check_url=f"http://127.0.0.1:{dead}"),
                 ros=RosSettings(master="localhost", port=dead))
    (tmp_path / "hosts").write_text("127.0.0.1 localhost\n")
    got = await _run_all(_ctx(tmp_path, s))
    assert len(got) == 32
    for cid, r in got.items():
        assert not r.summary.startswith("the check failed unexpectedly"), (cid, r.summary)
        assert data.undeclared(cid, r.data) == [], (cid, r.data)


async def test_run_check_refuses_an_undeclared_key_in_strict_mode(monkeypatch, tmp_path):
    async def renamed(ctx: CheckContext) -> Outcome:
        return Outcome(Status.PASS, "ok", [], {"port": 1, "listenning": True})

    spec = CheckSpec("router.listener", "router", "a check with a renamed key", renamed)
    ctx = _ctx(tmp_path, Settings())
    monkeypatch.setenv(data.STRICT_ENV, "1")
    with pytest.raises(data.UndeclaredKeyError, match="listenning"):
        await run_check(spec, ctx)
    monkeypatch.setenv(data.STRICT_ENV, "0")
    r = await run_check(spec, ctx)  # outside the tests: reported as it is, never a crash
    assert r.data == {"port": 1, "listenning": True}


async def test_the_runners_timeout_is_told_apart_from_a_wait_inside_a_check(tmp_path):
    """"no verdict within S s (timed out)" is the runner's own word for a check that overran its
    timeout; a wait inside a check that gave up and got out (a TimeoutError) is not that."""
    async def overruns(ctx: CheckContext) -> Outcome:
        await asyncio.sleep(5)
        return Outcome(Status.PASS, "late", [], {})

    async def lets_a_wait_out(ctx: CheckContext) -> Outcome:
        await asyncio.wait_for(asyncio.sleep(5), 0.05)
        return Outcome(Status.PASS, "never", [], {})

    ctx = _ctx(tmp_path, Settings())
    ctx.timeout_s = 0.3
    late = await run_check(CheckSpec("ros.env", "ros", "t", overruns), ctx)
    assert late.summary == "no verdict within 0.3 s (timed out)"
    inner = await run_check(CheckSpec("ros.env", "ros", "t", lets_a_wait_out), ctx)
    assert inner.status == Status.FAIL and inner.duration_s < 0.3
    assert inner.summary.startswith("the check failed unexpectedly: a wait inside it timed out")


# --------------------------------------------------------------------------- consumers
def test_view_refuses_undeclared_keys_at_every_level():
    raw = {"ports": [{"port": 5000, "reachable": True, "listener": True, "via": "echoip"}],
           "test_port": 5000, "test_port_open": True, "public_ip": "203.0.113.9"}
    v = data.view("router.port_open", raw)
    assert v["test_port"] == 5000 and v.get("public_ip") == "203.0.113.9"
    assert v["ports"][0]["via"] == "echoip"
    with pytest.raises(data.UndeclaredKeyError):
        v.get("test_port_opened")
    with pytest.raises(data.UndeclaredKeyError):
        v["ports"][0].get("open")
    peers = data.view("linux.ssh", {"peers": {"sami": {"ok": True, "failure": None}}})["peers"]
    assert peers["sami"]["ok"] is True and peers["sami"].get("fingerprint") is None
    with pytest.raises(data.UndeclaredKeyError):
        peers["sami"].get("fingerprints")
    node = data.view("ros.node_uris", {"unreachable": [{"node": "/talker", "from": "here"}]})
    assert node["unreachable"][0]["from"] == "here"


def test_undeclared_names_nested_paths():
    raw = {"peers": {"sami": {"ok": True, "failure": None, "extra": 1}}, "oops": 2}
    assert data.undeclared("linux.chat_in", raw) == ["linux.chat_in.peers['sami'].extra",
                                                     "linux.chat_in.oops"]
    assert data.undeclared("ros.pubsub_in", {"peer": "", "ok": False,
                                             "peers": {"sami": {"peer": "sami", "ok": True,
                                                                "failed_hop": None}}}) == []


async def test_ros2_checks_report_only_declared_keys_against_dead_loopback_services(tmp_path):
    """[ros] version = 2: the ros2.* checks (and the ROS 2 branches of router.port_open and the
    Linux chats) against a master and a peer on loopback ports nobody serves."""
    dead = free_port()
    for role in ("master", "member"):
        s = Settings(this=ThisComponent(name="localhost" if role == "master" else "me",
                                        local_ip="127.0.0.1", role=role),
                     peers=[Peer(name="localhost" if role == "member" else "peer",
                                 local_ip="127.0.0.1", public_ip="127.0.0.1",
                                 ssh_user="nobody", ssh_port=dead)],
                     probe=ProbeSettings(port=free_port(),
                                         public_ip_urls=[f"http://127.0.0.1:{dead}/ip"],
                                         port_check_url=f"http://127.0.0.1:{dead}"),
                     ros=RosSettings(master="localhost", version=2, zenoh_port=dead))
        (tmp_path / "hosts").write_text("127.0.0.1 localhost\n")
        got = await _run_all(_ctx(tmp_path, s))
        assert {c for c, r in got.items() if r.status.value != "skip" or r.summary.startswith(
            "skipped: this check is for")} >= {"ros2.env", "ros2.router", "ros2.graph"}
        for cid, r in got.items():
            assert not r.summary.startswith("the check failed unexpectedly"), (cid, r.summary)
            assert data.undeclared(cid, r.data) == [], (cid, r.data)
        for cid in ("ros.env", "ros.master", "ros.node_uris", "ros.pubsub_out", "ros.pubsub_in"):
            assert got[cid].status.value == "skip" and "ROS 1" in got[cid].summary, cid
