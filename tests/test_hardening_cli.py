"""Issue 15, CLI and probe server: bad arguments and inputs are exit 2 with a message, never a
traceback; the probe server answers 400 to what it cannot read.

Reproduced: ``probe-server --connect-timeout nan`` (also inf, 1e9) was accepted and with nan every
open port read "closed"; ``undo --state-dir FILE`` and ``report --from-json`` with a wrong type or
100k-deep JSON ended in tracebacks; ``GET /port/1²³`` got an empty reply and a logged traceback.
"""

from __future__ import annotations

import asyncio
import json
import logging
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.cli import build_parser
from rosnet_tui.core.net.probe_server import ProbeLimits, ProbeServer
from rosnet_tui.core.wizard import report
from tests.hardening_tally import tally
from tests.test_probe_server import Listener, http

REPO = Path(__file__).resolve().parents[1]


def rosnet(*args: str, timeout: float = 30, input: str | None = None
           ) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rosnet_tui", *args], capture_output=True,
                          text=True, timeout=timeout, env=dict(os.environ, PYTHONPATH=str(REPO)),
                          cwd=REPO, input=input, stdin=None if input is not None
                          else subprocess.DEVNULL)


# =========================================================================== float options
# Every float option of every command, with its documented range.
FLOAT_OPTIONS = [
    (["check"], "--timeout", 0.1, 120),
    (["sync"], "--interval", 1, 86400),
    (["probe-server"], "--connect-timeout", 0.1, 60),
]
BAD_FLOATS = ["nan", "NaN", "inf", "-inf", "Infinity", "1e9", "1e400", "-1", "0", "-0.0",
              "abc", "", " ", "0x10", "1,5", "1_000"]


def _parse(argv: list[str]):
    return build_parser(argv).parse_args(argv)


@pytest.mark.parametrize("cmd, opt, lo, hi", FLOAT_OPTIONS, ids=[o[1] for o in FLOAT_OPTIONS])
def test_every_float_option_refuses_non_finite_and_out_of_range_values(cmd, opt, lo, hi, capsys):
    bad = BAD_FLOATS + [repr(hi * 1.001), repr(lo / 2)]
    for value in bad:
        with pytest.raises(SystemExit) as e:
            _parse([*cmd, f"{opt}={value}"])
        assert e.value.code == 2, value
        err = capsys.readouterr().err
        assert opt in err and "Traceback" not in err, (value, err)
    for value in (lo, hi, (lo + hi) / 2):
        assert getattr(_parse([*cmd, opt, repr(value)]), opt[2:].replace("-", "_")) == value
    tally("cli", len(bad), len(bad), "float options")


@pytest.mark.parametrize("cmd, opt, lo, hi", FLOAT_OPTIONS, ids=[o[1] for o in FLOAT_OPTIONS])
def test_every_float_option_states_its_range_in_the_help(cmd, opt, lo, hi, capsys):
    with pytest.raises(SystemExit):
        _parse([*cmd, "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert f"{lo:g}-{hi:g}" in out, out


@pytest.mark.parametrize("opt, lo, hi", [("--rate-limit", 1, 1_000_000), ("--max-concurrent", 1, 1024)])
def test_the_probe_servers_whole_number_options_are_bounded_too(opt, lo, hi, capsys):
    for value in ("0", "-3", str(hi + 1), "1e9", "nan", "1.5", "9" * 5000):
        with pytest.raises(SystemExit) as e:
            _parse(["probe-server", opt, value])
        assert e.value.code == 2 and opt in capsys.readouterr().err
    assert getattr(_parse(["probe-server", opt, str(hi)]), opt[2:].replace("-", "_")) == hi
    tally("cli", 7, 7, "int options")


def test_probe_server_with_nan_exits_2_and_never_listens():
    started = time.monotonic()
    r = rosnet("probe-server", "--listen", "127.0.0.1:0", "--connect-timeout", "nan", timeout=20)
    assert r.returncode == 2 and "--connect-timeout" in r.stderr and "listening" not in r.stderr
    assert time.monotonic() - started < 15
    tally("cli", 1, 1, "probe-server nan")


# =========================================================================== undo --state-dir
def test_undo_with_a_state_dir_that_is_not_a_folder_exits_2(tmp_path):
    f = tmp_path / "a-file"
    f.write_text("x")
    cases = [f, f / "below", Path("/dev/null")]
    for sd in cases:
        r = rosnet("undo", "--yes", "--state-dir", str(sd))
        assert r.returncode == 2, (sd, r.stderr)
        assert "Traceback" not in r.stderr and "--state-dir" in r.stderr, r.stderr
    assert f.read_text() == "x"
    tally("cli", len(cases), len(cases), "undo --state-dir")


# =========================================================================== report --from-json
GOOD_CHECK = {"id": "isp.internet", "step": "isp", "status": "pass", "summary": "ok",
              "evidence": ["x"], "duration_s": 0.1, "timeout_s": 3.0, "data": {}}


def _doc(**change) -> str:
    check = dict(GOOD_CHECK)
    check.update(change.pop("check", {}))
    d = {"checks": [check]}
    d.update(change)
    return json.dumps(d)


BAD_REPORTS = {
    "duration-str": _doc(check={"duration_s": "abc"}),
    "duration-list": _doc(check={"duration_s": [1]}),
    "duration-dict": _doc(check={"duration_s": {"a": 1}}),
    "duration-nan": _doc(check={"duration_s": float("nan")}),
    "timeout-inf": _doc(check={"timeout_s": float("inf")}),
    "timeout-neg": _doc(check={"timeout_s": -5}),
    "duration-true": _doc(check={"duration_s": True}),
    "status-int": _doc(check={"status": 3}),
    "status-list": _doc(check={"status": ["pass"]}),
    "id-int": _doc(check={"id": 7}),
    "checks-dict": '{"checks": {"a": 1}}',
    "checks-of-lists": '{"checks": [[1, 2]]}',
    "top-list": "[1, 2, 3]",
    "top-str": '"checks"',
    "settings-list": _doc(settings=[1, 2]),
    "settings-this-str": _doc(settings={"this": "sami"}),
    "settings-name-int": _doc(settings={"this": {"name": 5}}),
    "settings-peers-ints": _doc(settings={"peer": [1, 2]}),
    "settings-peer-name-list": _doc(settings={"peer": [{"name": ["a"]}]}),
    "settings-port-str": _doc(settings={"ros": {"port": "x"}}),
    "settings-timeout-str": _doc(settings={"checks": {"timeout_s": "x"}}),
    "report-str": _doc(report="yesterday"),
    "report-generated-list": _doc(report={"generated": [1]}),
    "environment-list": _doc(environment=[1]),
    "environment-values": _doc(environment={"ROS_IP": [1, 2], "ROS_X": {"a": 1}}),
    "data-list": _doc(check={"data": [1]}),
    "evidence-dict": _doc(check={"evidence": {"a": 1}}),
    "deep-100k": "[" * 100_000 + "]" * 100_000,
    "deep-in-check": _doc()[:-2] + ', "extra": ' + "[" * 50_000 + "]" * 50_000 + "}]}",
    "deep-objects": '{"a":' * 20_000 + "1" + "}" * 20_000,
    "big-int": '{"checks": [], "x": 1' + "0" * 5000 + "}",
    "nul": '{"checks": [{"id": "\\u0000", "status": "pass"}]}',
    "surrogate": '{"checks": [{"id": "\\ud800", "status": "pass"}]}',
}


@pytest.mark.parametrize("name", sorted(BAD_REPORTS))
def test_report_from_json_with_bad_types_or_depth_is_exit_2_or_a_report(tmp_path, name):
    src = tmp_path / "in.json"
    src.write_text(BAD_REPORTS[name])
    for fmt in ("md", "json"):
        r = rosnet("report", "--format", fmt, "--from-json", str(src), "--config",
                   str(tmp_path / "none.toml"))
        assert "Traceback" not in r.stderr, r.stderr[-3000:]
        assert r.returncode in (0, 1, 2), r.returncode
        if r.returncode == 2:
            lines = [x for x in r.stderr.splitlines() if x.strip()]
            assert len(lines) == 1 and lines[0].startswith("rosnet-tui report:"), r.stderr[:500]
            assert len(lines[0]) < 400
    tally("cli", 1, 1, "report --from-json")


def test_report_from_json_reads_a_bounded_amount(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    zero = tmp_path / "zero.json"
    zero.symlink_to("/dev/zero")
    for src in (fifo, zero, tmp_path):
        started = time.monotonic()
        r = rosnet("report", "--from-json", str(src), timeout=20)
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stderr[-500:]
        assert time.monotonic() - started < 15
    r = rosnet("report", "--from-json", "-", input="[" * 100_000)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    tally("cli", 4, 4, "report reads")


_json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**20), 10**20) | st.floats()
    | st.text(max_size=10),
    lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=6), kids,
                                                              max_size=3),
    max_leaves=12)
_keys = st.sampled_from(["id", "step", "status", "summary", "evidence", "duration_s",
                         "timeout_s", "data"])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(_keys, _json_values, max_size=8),
       st.dictionaries(st.sampled_from(["settings", "report", "environment", "checks"]),
                       _json_values, max_size=3),
       st.sampled_from(["pass", "warn", "fail", "skip", "other"]))
def test_property_saved_results_make_a_report_or_a_report_error(tmp_path_factory, check, top,
                                                                status):
    check.setdefault("id", "isp.internet")
    check.setdefault("status", status)
    doc = {"checks": [check]}
    doc.update({k: v for k, v in top.items() if k != "checks"})
    path = tmp_path_factory.mktemp("r") / "in.json"
    path.write_text(json.dumps(doc))
    try:
        results, saved, meta = report.load_results_json(path)
        from rosnet_tui.core.config.settings_model import Settings

        d = report.build_report(results, saved or Settings(), source="x",
                                environment=meta.get("environment"))
        report.render_markdown(d)
        report.render_json(d)
    except report.ReportError as exc:
        assert "\n" not in str(exc)
    tally("cli", 1, 1, "property: report input")


# =========================================================================== probe server
@pytest.fixture
async def server():
    srv = ProbeServer("127.0.0.1", 0, ProbeLimits(connect_timeout_s=1.0))
    await srv.start()
    yield srv
    await srv.close()


@pytest.mark.parametrize("path", ["/port/1²³", "/port/²³⁴⁵⁶", "/port/¹²³⁴⁵", "/port/1234¼",
                                  "/port/12345\u00a0", "/port/%31%32%33%34%35", "/port/+12345",
                                  "/port/012345", "/port/" + "1" * 5000, "/port/1_2345"],
                         ids=["sup23", "sup", "sup1", "quarter", "nbsp", "percent", "plus",
                              "six-digits", "5000-digits", "underscore"])
async def test_port_path_that_is_not_plain_ascii_digits_is_a_400(server, path, caplog):
    raw = f"GET {path} HTTP/1.1\r\nHost: x\r\n\r\n".encode("latin-1", "replace")
    with caplog.at_level(logging.INFO, logger="rosnet_tui.probe_server"):
        status, _, body = await http(server.port, raw=raw)
        for _ in range(500):    # bounded (5 s): the request's last word is its access line
            if any(r.name == "rosnet_tui.probe_server" for r in caplog.records):
                break
            await asyncio.sleep(0.01)
    assert status in (400, 431) and "error" in json.loads(body)
    assert not server.recent_connect_backs
    assert [r.getMessage().split()[3] for r in caplog.records
            if r.name == "rosnet_tui.probe_server"] == [str(status)]
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]
    tally("probe-server", 1, 1, "port paths")


async def test_ascii_digits_still_work(server):
    listener = Listener()
    try:
        status, _, body = await http(server.port, f"/port/{listener.port}")
        assert status == 200 and json.loads(body)["reachable"] is True
    finally:
        listener.close()


@settings(max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.binary(min_size=0, max_size=60), st.sampled_from([b"GET ", b"POST ", b"", b"GET /port/"]))
def test_property_any_request_line_gets_an_answer_or_a_clean_close(line, prefix):
    async def go() -> None:
        srv = ProbeServer("127.0.0.1", 0, ProbeLimits(connect_timeout_s=0.2, request_timeout_s=1))
        await srv.start()
        errors: list = []
        loop = asyncio.get_running_loop()
        loop.set_exception_handler(lambda lp, ctx: errors.append(ctx))
        try:
            r, w = await asyncio.open_connection("127.0.0.1", srv.port)
            w.write(prefix + line.replace(b"\n", b" ") + b" HTTP/1.1\r\n\r\n")
            await w.drain()
            data = await asyncio.wait_for(r.read(), 5)
            w.close()
            assert data == b"" or data.startswith(b"HTTP/1.1 "), data[:80]
            if data.startswith(b"HTTP/1.1 200") and b"/port/" in prefix:
                assert all(ip == "127.0.0.1" for ip, _ in srv.recent_connect_backs)
            await asyncio.sleep(0.01)
        finally:
            await srv.close()
        assert not errors, errors

    asyncio.run(go())
    tally("probe-server", 1, 1, "property: request lines")
