"""Rows 2, 3, 6 and 9 (bench/deadlink_row.py): on the network lab (tests/lab: root + network namespaces; skipped otherwise).

All traffic stays inside the lab's namespaces. Every command runs through ``lab.run`` (bounded,
its process tree killed on timeout); the lab is destroyed at the end, whatever happens.
"""

from __future__ import annotations

import json
import random
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from bench import deadlink_row
from bench.compiled import compiled_copy, run_compiled
from bench.model import BenchError, Line, Options, RowResult, goal_ratio, median

BENCH = Path(__file__).resolve().parent
MANUAL_SCRIPT = BENCH / "manual_check.sh"
CHECK_TIMEOUT = 120.0       # the bound of one `rosnet-tui check` run
_COMPILED: Path | None = None   # a byte-compiled copy of the package (compiled_copy)
TITLES = {2: "Full verification on the lab's healthy network, from a member and the master",
          3: "Bad news fast: every verdict within its timeout",
          6: "Address sync: master address change to member updated",
          9: "A dead link seen in seconds, and data again after it returns (ROS 2)"}


# Row 2's line for a session's first run, the last of the row (added after the others: their
# letters stay as the docs cite them).
COLD_MEASURE = "Full verification, a session's first run (wall time)"


def rosnet_check(lab: Any, host: str, state: Path, *extra: str, config: Path | None = None,
                 env: dict[str, str] | None = None) -> dict[str, Any]:
    """`rosnet-tui check --json` on *host* (all steps, both directions): wall time and verdicts.

    A verdict's margin is its duration minus the round's timeout_s (the lab's settings, or
    --timeout in *extra*): bad news must come within timeout_s + 0.5 s whatever the check's
    own, longer budget for a peer that answers.
    """
    base = float(extra[extra.index("--timeout") + 1]) if "--timeout" in extra else \
        float(lab.settings(host).checks.timeout_s)
    config = config or lab.config_path(host)  # written before the clock starts
    env = dict(env or lab.ros_env(host), XDG_STATE_HOME=str(state))
    if _COMPILED is not None:       # the byte-compiled copy (bench/compiled.py)
        env = run_compiled(env, _COMPILED)
    if env.get("ROSNET_TUI_WARM") != "0":
        warm_up(lab, host, config, env)
    t0 = time.monotonic()
    r = lab.rosnet(host, "check", "--json", "-q", "--config", str(config), *extra, env=env,
                   timeout=CHECK_TIMEOUT)
    wall = time.monotonic() - t0
    try:
        checks = json.loads(r.stdout)["checks"]
    except (ValueError, KeyError) as exc:
        raise BenchError(f"rosnet-tui check on {host} gave no JSON (exit {r.returncode}): "
                         f"{r.stderr[-500:]}") from exc
    margins = [(c["duration_s"] - base, c["id"], c["duration_s"], base) for c in checks]
    worst = max(margins)
    slowest = max(checks, key=lambda c: c["duration_s"])
    return {"wall_s": wall, "exit": r.returncode,
            "all_pass": r.returncode == 0 and all(c["status"] == "pass" for c in checks),
            "statuses": {c["id"]: c["status"] for c in checks},
            "durations": {c["id"]: c["duration_s"] for c in checks},
            "waits": waits_seen(checks),
            "worst_margin_s": worst[0], "worst_check": f"{worst[1]} {worst[2]:.2f}/{worst[3]:g} s",
            "slowest_check_s": slowest["duration_s"], "slowest_check": slowest["id"]}


def warm_up(lab: Any, host: str, config: Path, env: dict[str, str]) -> None:
    """A re-run, as a technician's every run after the first: the warm process the first run
    of `rosnet-tui check` leaves (rosnet_tui/cli/warm.py) is made ready first, not timed. Its
    socket is named by what the command on *host* with *env* sees; a run is made, and the socket
    waited for, only when it is not there yet."""
    ask = "from rosnet_tui.cli import warm; print(warm.socket_path() or '')"
    r = lab.run(host, [sys.executable, "-c", ask], env=env, timeout=30)
    path = Path(r.stdout.strip()) if r.returncode == 0 and r.stdout.strip() else None
    if path is None:
        raise BenchError(f"no warm socket can be named on {host}: {r.stderr[-300:]}")
    if path.exists():
        return
    lab.rosnet(host, "check", "--json", "-q", "--config", str(config), env=env,
               timeout=CHECK_TIMEOUT)
    deadline = time.monotonic() + 20
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    if not path.exists():
        raise BenchError(f"the warm process on {host} did not come up within 20 s")


def waits_seen(checks: list[dict[str, Any]]) -> list[str]:
    """The silences security.outsider waited out in a healthy run (issue 32): a port the port
    checker judged only when its own connect timeout ran out (the lab's checker waits 2 s), and
    a TLS verdict read from silence instead of an answer."""
    out = []
    for c in checks:
        if c["id"] != "security.outsider":
            continue
        d = c.get("data") or {}
        out += [f"port checker, port {p}: {s:.2f} s" for p, s in
                (d.get("outsider_s") or {}).items() if s is not None and s >= 1.9]
        out += [f"TLS {k}: {a.get('detail')}" for k, a in (d.get("attempts") or {}).items()
                if str(a.get("detail") or "").startswith("no verdict within")]
    return out


# =============================================================================== row 2
def manual_check(lab: Any, rep: int, cap: float) -> dict[str, Any]:
    """The procedure's manual tests one after another with the standard tools (bench/manual_check.sh)
    on the laptop, the robot its peer."""
    from tests.lab.lab import LISTENER, ROS_PYTHON, TALKER

    ports = random.SystemRandom().sample(range(20000, 30000), 3)
    env = dict(lab.ros_env("laptop"), PEER=lab.addr.ROBOT_NAME, SELF=lab.addr.LAPTOP_NAME,
               PEER_USER="root", IP_URL=lab.addr.PUBLIC_IP_URL, PORT_URL=lab.addr.PROBE_URL,
               PORT1=str(ports[0]), PORT2=str(ports[1]), PORT3=str(ports[2]),
               TALKER=str(TALKER), LISTENER=str(LISTENER), ROS_PY=ROS_PYTHON,
               TOPIC=f"/bench_manual_{rep}_{random.randrange(10**6)}", CAP=str(int(cap)))
    t0 = time.monotonic()
    r = lab.run("laptop", ["bash", str(MANUAL_SCRIPT)], env=env, timeout=cap * 12)
    wall = time.monotonic() - t0
    lines = [ln for ln in r.stdout.splitlines() if ln.startswith(("PASS", "FAIL"))]
    return {"wall_s": wall, "exit": r.returncode, "lines": lines,
            "all_pass": r.returncode == 0 and bool(lines) and all(ln.startswith("PASS")
                                                                  for ln in lines),
            "stderr": r.stderr[-500:]}


def row2_full(lab: Any, opts: Options, state: Path) -> RowResult:
    res = RowResult(2, TITLES[2])
    from tests.lab.firewall import secured

    lab.reset()
    lab.start_roscore()
    app_runs, base_runs, master_runs, cold_runs = [], [], [], []
    cold_env = dict(lab.ros_env("laptop"), ROSNET_TUI_WARM="0")
    for i in range(opts.reps):
        order = ("app", "cold", "base", "master")
        for who in (order if i % 2 == 0 else order[::-1]):
            if who == "base":       # the manual procedure, as before issue 22: no firewall (its
                base_runs.append(manual_check(lab, i, 60.0))   # port checker is no peer)
                continue
            with secured(lab):      # ROS 1 as the product sets it up: the peers-only firewall
                if who == "app":    # a re-run: the warm process of the first run serves it
                    app_runs.append(rosnet_check(lab, "laptop", state / "laptop"))
                elif who == "cold":  # a first run: no warm process
                    cold_runs.append(rosnet_check(lab, "laptop", state / "laptop", env=cold_env))
                else:
                    master_runs.append(rosnet_check(lab, "robot", state / "robot"))
    ln = Line(2, "Full verification (wall time)", "s",
              [r["wall_s"] for r in app_runs], [r["wall_s"] for r in base_runs],
              baseline="manual tests with standard tools, one after another (script)",
              goal="<= 0.15x")
    goal_ratio(ln, 0.15)
    app_ok = all(r["all_pass"] for r in app_runs)
    base_ok = all(r["all_pass"] for r in base_runs)
    n_checks = len(app_runs[0]["statuses"]) if app_runs else 0
    n_tests = len(base_runs[0]["lines"]) if base_runs else 0
    ln.note = (f"a re-run (as every run after a session's first: served by the warm process "
               f"the first one left), all steps, both ways, from the laptop: {n_checks} checks "
               f"vs {n_tests} manual tests; same verdict (all good): "
               f"{'yes' if app_ok and base_ok else 'NO'}; slowest check "
               f"{median([r['slowest_check_s'] for r in app_runs]):.2f} s; "
               f"{_waits_note(app_runs)}; with the peers-only firewall loaded on both, as "
               "the product sets ROS 1 up; rosnet-tui byte-compiled, as installed")
    if not (app_ok and base_ok):
        ln.status = "error"
        bad_app = sorted({k for r in app_runs for k, v in r["statuses"].items() if v != "pass"})
        bad_base = sorted({x for r in base_runs for x in r["lines"] if x.startswith("FAIL")})
        ln.note += f"; not all good: rosnet-tui {bad_app}, manual {bad_base}"
    cold = Line(2, COLD_MEASURE, "s",
                [r["wall_s"] for r in cold_runs], [r["wall_s"] for r in base_runs],
                baseline="manual tests with standard tools, one after another (script)",
                goal="none (re-runs: the line above)")
    cold_ok = all(r["all_pass"] for r in cold_runs)
    cold.note = (f"the same from the laptop with no warm process (ROSNET_TUI_WARM=0: a cold "
                 f"process loads everything; the first run after checks.keep_warm_s idle); all "
                 f"good: {'yes' if cold_ok else 'NO'}; slowest check "
                 f"{median([r['slowest_check_s'] for r in cold_runs]):.2f} s")
    if not cold_ok:
        cold.status = "error"
    seat = Line(2, "Full verification from the master's seat (wall time)", "s",
                [r["wall_s"] for r in master_runs], [r["wall_s"] for r in app_runs],
                baseline="the same from a member's seat (the laptop)", goal="<= 1.2x")
    goal_ratio(seat, 1.2)
    master_ok = all(r["all_pass"] for r in master_runs)
    seat.note = (f"all steps, both ways, from the robot (the ROS master) against the laptop: "
                 f"{len(master_runs[0]['statuses']) if master_runs else 0} checks; all good: "
                 f"{'yes' if master_ok else 'NO'}; slowest check "
                 f"{median([r['slowest_check_s'] for r in master_runs]):.2f} s on the master, "
                 f"{median([r['slowest_check_s'] for r in app_runs]):.2f} s on the member")
    if not master_ok:
        seat.status = "error"
        bad = sorted({k for r in master_runs for k, v in r["statuses"].items() if v != "pass"})
        seat.note += f"; not all good on the master: {bad}"
    tls, tls_details = _row2_tls(lab, opts, state)
    relay, relay_details = _row2_relay(lab, opts, state, tls_details["ros2_mtls_runs"])
    res.lines = [ln, seat, *tls, relay, cold]
    res.details = {"app_runs": app_runs, "base_runs": base_runs, "master_runs": master_runs,
                   "cold_runs": cold_runs,
                   **tls_details, **relay_details}
    return res


def _row2_relay(lab: Any, opts: Options, state: Path, direct: list[dict[str, Any]]
                ) -> tuple[Line, dict[str, Any]]:
    """ROS 2 through the relay (issue 30, tests/lab/relay.py): the member's full verification
    when both sites meet at the relay against the direct, forwarded case (*direct*: the same
    seat's runs with mutual TLS); at most 1.5x."""
    from tests.lab.relay import RelayWorld

    runs: list[dict[str, Any]] = []
    with RelayWorld(lab) as w:
        for _ in range(opts.reps):
            runs.append(rosnet_check(lab, "laptop", state / "relay", config=w.config_path("laptop"),
                                     env=w.env("laptop")))
    line = Line(2, "Full verification from a member through the relay, ROS 2 (wall time)", "s",
                [r["wall_s"] for r in runs], [r["wall_s"] for r in direct],
                baseline="the same seat, the master's port forwarded (no relay)", goal="<= 1.5x")
    goal_ratio(line, 1.5)
    bad = sorted({k for r in runs for k, v in r["statuses"].items() if v not in ("pass", "skip")})
    run = _median_run(runs) if runs else None
    line.note = (f"all steps from the laptop (a member) with both routers dialling the relay "
                 f"(mutual TLS; no Zenoh port forwarded): {len(runs[0]['statuses']) if runs else 0}"
                 f" checks; every check passing: {'yes' if not bad else 'NO'}"
                 + (f"; slowest check {run['slowest_check']} {run['slowest_check_s']:.2f} s"
                    if run else "") + f"; {_waits_note(runs)}")
    if bad:
        line.status = "error"
        line.note += f"; not passing: {bad}"
    return line, {"ros2_relay_runs": runs}


def _waits_note(runs: list[dict[str, Any]]) -> str:
    n = sum(len(r["waits"]) for r in runs)
    return f"silences waited out: {n} in {len(runs)} runs" + (
        f" ({'; '.join(sorted({w for r in runs for w in r['waits']}))})" if n else "")


def every_seat(row: int, measure: str, seats: dict[str, list[dict[str, Any]]], limit: float,
               what: str) -> Line:
    """A line for every seat's full verification: the slowest seat's runs against *limit*
    seconds (its median), each seat's median and slowest check in the note."""
    def ok(r: dict[str, Any]) -> bool:       # skips: checks that do not apply to that seat
        return not [k for k, v in r["statuses"].items() if v not in ("pass", "skip")]

    meds = {h: median([r["wall_s"] for r in rs]) or 0.0 for h, rs in seats.items()}
    worst = max(meds, key=lambda h: meds[h]) if meds else ""
    ln = Line(row, measure, "s", [r["wall_s"] for r in seats.get(worst, [])], [],
              goal=f"<= {limit:g} s")
    ln.met = bool(meds) and max(meds.values()) <= limit
    good = all(ok(r) for rs in seats.values() for r in rs)
    runs = [r for rs in seats.values() for r in rs]
    ln.note = (f"{what}; the slowest seat shown ({worst}); each seat: " + ", ".join(
        f"{h} {meds[h]:.2f} s (slowest check "
        f"{_median_run(rs)['slowest_check']} {_median_run(rs)['slowest_check_s']:.2f} s)"
        for h, rs in seats.items()) + f"; every check passing: {'yes' if good else 'NO'}; "
        + _waits_note(runs))
    if not good:
        ln.status = "error"
        ln.note += "; not passing: " + ", ".join(sorted({
            f"{h}: {k}" for h, rs in seats.items() for r in rs
            for k, v in r["statuses"].items() if v not in ("pass", "skip")}))
    return ln


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    return sorted(runs, key=lambda r: r["wall_s"])[len(runs) // 2]


def _row2_tls(lab: Any, opts: Options, state: Path) -> tuple[list[Line], dict[str, Any]]:
    """ROS 2 from the member's seat: full verification with mutual TLS (the default) against
    the same with [ros] security = "none" (issue 22: TLS adds at most 0.2 s); and with mutual
    TLS from the master's seat against the member's (issue 25: at most 1.2x)."""
    from tests.lab.ros2 import Ros2World

    lab.stop_roscore()
    runs: dict[str, list[dict[str, Any]]] = {"mtls": [], "none": [], "master": []}
    with Ros2World(lab) as w:
        for i in range(opts.reps):
            for mode in (("mtls", "none") if i % 2 == 0 else ("none", "mtls")):
                w.set_security(mode)       # configs rewritten, routers restarted: not timed
                runs[mode].append(rosnet_check(lab, "laptop", state / f"ros2-{mode}",
                                               config=w.config_path("laptop"),
                                               env=w.env("laptop")))
                if mode == "mtls":         # and from the master's seat, the robot
                    runs["master"].append(rosnet_check(lab, "robot", state / "ros2-master",
                                                       config=w.config_path("robot"),
                                                       env=w.env("robot")))
    line = Line(2, "Full verification, ROS 2 with mutual TLS (wall time)", "s",
                [r["wall_s"] for r in runs["mtls"]], [r["wall_s"] for r in runs["none"]],
                baseline='the same with [ros] security = "none"', goal="<= +0.2 s")
    a, b = line.app_median, line.base_median
    line.met = None if a is None or b is None else a - b <= 0.2

    def bad(r: dict[str, Any]) -> list[str]:     # skips: checks that do not apply to a member
        return [k for k, v in r["statuses"].items() if v not in ("pass", "skip")]

    ok = all(not bad(r) for r in runs["mtls"]) and all(
        bad(r) == ["security.outsider"] for r in runs["none"])
    n = len(runs["mtls"][0]["statuses"]) if runs["mtls"] else 0
    line.note = (f"all steps from the laptop (a member) on ROS 2: {n} checks; TLS adds "
                 f"{(a or 0) - (b or 0):+.2f} s; all good under mTLS, only security.outsider "
                 f"failing under none: {'yes' if ok else 'NO'}")
    if not ok:
        line.status = "error"
        line.note += "; " + "; ".join(f"{m}: {sorted({x for r in rs for x in bad(r)})}"
                                      for m, rs in runs.items())
    seat = Line(2, "Full verification from the master's seat, ROS 2 (wall time)", "s",
                [r["wall_s"] for r in runs["master"]], [r["wall_s"] for r in runs["mtls"]],
                baseline="the same from a member's seat (the laptop)", goal="<= 1.2x")
    goal_ratio(seat, 1.2)
    master_ok = all(not bad(r) for r in runs["master"])
    seat.note = (f"all steps from the robot (the master, its Zenoh router) on ROS 2 with mutual "
                 f"TLS: {len(runs['master'][0]['statuses']) if runs['master'] else 0} checks; all "
                 f"good: {'yes' if master_ok else 'NO'}; slowest check "
                 f"{median([r['slowest_check_s'] for r in runs['master']]):.2f} s on the master, "
                 f"{median([r['slowest_check_s'] for r in runs['mtls']]):.2f} s on the member")
    if not master_ok:
        seat.status = "error"
        seat.note += f"; not all good: {sorted({x for r in runs['master'] for x in bad(r)})}"
    seats = every_seat(2, "ROS 2 with mutual TLS, two sites: every seat's full verification "
                          "(wall time)", {"laptop (member)": runs["mtls"],
                                          "robot (master)": runs["master"]}, 0.9,
                       "ROS 2 as users run it (mutual TLS, the default), all steps both ways")
    return [line, seat, seats], {"ros2_mtls_runs": runs["mtls"], "ros2_none_runs": runs["none"],
                                 "ros2_master_runs": runs["master"]}


def row2_three_sites(opts: Options, state: Path, log: Callable[[str], None]) -> RowResult:
    """ROS 2 with mutual TLS on the three-site lab (tests/lab/fleet.py: a master, two members):
    every seat's full verification."""
    from tests.lab import LabUnavailable
    from tests.lab.fleet import Fleet
    from tests.lab.fleet_ros2 import FleetRos2

    res = RowResult(2, TITLES[2])
    fleet = Fleet(3)
    try:
        log("row 2: building the three-site lab")
        try:
            fleet.build()
        except LabUnavailable as exc:
            res.status, res.reason = "skipped", str(exc)
            return res
        seats: dict[str, list[dict[str, Any]]] = {h: [] for h in fleet.COMPUTERS}
        with FleetRos2(fleet) as w:
            for i in range(opts.reps):
                for h in (fleet.COMPUTERS if i % 2 == 0 else list(reversed(fleet.COMPUTERS))):
                    seats[h].append(rosnet_check(fleet, h, state / f"three-{h}",
                                                 config=w.config_path(h), env=w.env(h)))
        names = {h: f"{h} ({'master' if h == fleet.master else 'member'})" for h in seats}
        res.lines.append(every_seat(2, "ROS 2 with mutual TLS, three sites: every seat's full "
                                       "verification (wall time)",
                                    {names[h]: rs for h, rs in seats.items()}, 1.1,
                                    "a master and two members (tests/lab/fleet.py), all steps "
                                    "both ways"))
        res.details = {"three_site_runs": seats}
    finally:
        fleet.destroy()
    return res


# =============================================================================== row 3
def _scenarios(lab: Any) -> list[dict[str, Any]]:
    from tests.lab.lab import ROS_PYTHON, TALKER

    ssh = ["ssh", "-o", "BatchMode=yes"]
    robot, laptop = lab.addr.ROBOT_NAME, lab.addr.LAPTOP_NAME
    return [
        {"name": "master down", "short": "Master down", "host": "laptop", "variant": None, "master": False,
         "tools": [("rostopic list", ["rostopic", "list"]),
                   ("talker (a rospy node)", [ROS_PYTHON, str(TALKER), "/bench_dead_master"])]},
        {"name": "port forwarding removed on the robot's modem, seen from the laptop",
         "short": "No forwarding", "host": "laptop",
         "variant": "no_forwarding", "master": True,
         "tools": [("ssh", [*ssh, f"root@{robot}", "true"]),
                   ("nc -z (test port)", ["nc", "-z", robot, "12345"]),
                   ("rostopic list", ["rostopic", "list"])]},
        {"name": "the laptop unplugged, seen from the robot", "short": "Peer unplugged",
         "host": "robot", "variant": "unplugged",
         "master": True,
         "tools": [("ssh", [*ssh, f"root@{laptop}", "true"]),
                   ("nc -z (test port)", ["nc", "-z", laptop, "12345"])]},
        {"name": "the robot unplugged, its modem dropping what it forwards (no ICMP error "
                 "either), seen from the laptop", "short": "Robot unplugged (silent)",
         "host": "laptop", "variant": "unplugged", "options": {"side": "robot", "silent": True},
         "master": True,
         "tools": [("ssh", [*ssh, f"root@{robot}", "true"]),
                   ("nc -z (test port)", ["nc", "-z", robot, "12345"]),
                   ("rostopic list", ["rostopic", "list"])]},
    ]


def _tool_time(lab: Any, host: str, argv: list[str], cap: float) -> dict[str, Any]:
    t0 = time.monotonic()
    try:
        r = lab.run(host, argv, timeout=cap, env=lab.ros_env(host))
        out = (r.stdout + r.stderr).strip().splitlines()
        return {"s": time.monotonic() - t0, "capped": False, "exit": r.returncode,
                "said": out[-1][:120] if out else ""}
    except subprocess.TimeoutExpired:
        return {"s": cap, "capped": True, "exit": None, "said": f"still waiting after {cap:g} s"}


def row3_bad_news(lab: Any, opts: Options, state: Path) -> RowResult:
    res = RowResult(3, TITLES[3])
    cap = opts.tool_cap_s
    extra = ("--timeout", "1") if opts.quick else ()
    margins: list[float] = []
    details = []
    for sc in _scenarios(lab):
        lab.reset()
        if sc["master"]:
            lab.start_roscore()
        else:
            lab.stop_roscore()
        ctx = lab.variant(sc["variant"], **sc.get("options", {})) if sc["variant"] \
            else _nothing()
        with ctx:
            runs = [rosnet_check(lab, sc["host"], state / sc["host"], *extra)
                    for _ in range(opts.reps)]
            tools = _time_tools(lab, sc["host"], sc["tools"], opts.reps, cap)
        per_rep = [sum(t["s"] for j, _, t in tools if j == i) for i in range(opts.reps)]
        worst = max(runs, key=lambda r: r["worst_margin_s"])
        margins += [r["worst_margin_s"] for r in runs]
        by_tool = {}
        for name, _argv in sc["tools"]:
            ts = [t for _, n, t in tools if n == name]
            s = median([t["s"] for t in ts])
            by_tool[name] = f"{s:.1f} s" + (" (capped)" if all(t["capped"] for t in ts) else "")
        ln = Line(3, f"{sc['short']}: every verdict", "s",
                  [r["wall_s"] for r in runs], per_rep,
                  baseline="standard tools with default settings, one after another",
                  goal="<= timeout_s+0.5 s")
        ln.met = all(r["worst_margin_s"] <= 0.5 for r in runs)
        ln.note = (f"{sc['name']}; worst margin {worst['worst_margin_s']:+.2f} s ({worst['worst_check']}); "
                   f"tools: " + ", ".join(f"{k} {v}" for k, v in by_tool.items())
                   + f"; each tool capped at {cap:g} s" + ("; checks at --timeout 1" if extra else ""))
        res.lines.append(ln)
        details.append({"scenario": sc["name"], "host": sc["host"], "rosnet_runs": runs,
                        "tools": [{"rep": i, "tool": n, **t} for i, n, t in tools]})
    lab.reset()
    lab.start_roscore()
    w = Line(3, "Worst verdict margin", "s", [max(margins)] if margins else [], [],
             goal="<= +0.5 s",
             note=f"a check's duration minus timeout_s (the round's, not the check's longer "
                  f"budget): the worst of {len(margins)} runs (all scenarios and "
                  "repetitions); negative = before the timeout")
    w.met = bool(margins) and max(margins) <= 0.5
    res.lines.append(w)
    res.details = {"scenarios": details, "worst_margins_s": margins}
    return res


def _time_tools(lab: Any, host: str, tools: list[tuple[str, list[str]]], reps: int, cap: float
                ) -> list[tuple[int, str, dict[str, Any]]]:
    """Time each tool *reps* times, each run capped at *cap* seconds, in bounded wall time.

    The first repetition runs the tools side by side (a few processes). A tool that hit the cap
    is waiting on a timer, not on the CPU: its other repetitions run all at once. A tool that
    finished runs its other repetitions one at a time, so no start-up competes with another.
    """
    def run_all(jobs: list[tuple[int, str, list[str]]]) -> list[tuple[int, str, dict[str, Any]]]:
        if not jobs:
            return []
        with ThreadPoolExecutor(max_workers=len(jobs)) as pool:
            futs = [(i, name, pool.submit(_tool_time, lab, host, argv, cap))
                    for i, name, argv in jobs]
            return [(i, name, f.result()) for i, name, f in futs]

    out = run_all([(0, name, argv) for name, argv in tools])
    capped = {name for _, name, t in out if t["capped"]}
    out += run_all([(i, name, argv) for i in range(1, reps) for name, argv in tools
                    if name in capped])
    for i in range(1, reps):
        for name, argv in tools:
            if name not in capped:
                out.append((i, name, _tool_time(lab, host, argv, cap)))
    return out


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


# =============================================================================== row 6
def row6_sync(lab: Any, opts: Options, state: Path) -> RowResult:
    from bench import sync_row

    return sync_row.run(lab, opts, state)


# =============================================================================== driver
def _skipped(rows: list[int], why: str, status: str = "skipped") -> list[RowResult]:
    return [RowResult(r, TITLES[r], status=status, reason=why) for r in rows]


def run_lab_rows(rows: list[int], opts: Options, log: Callable[[str], None]) -> list[RowResult]:
    wanted = [r for r in (2, 3, 6, 9) if r in rows]
    if not wanted:
        return []
    try:
        from tests.lab import Lab, LabUnavailable, lab_available
    except Exception as exc:  # e.g. the lab's own dependencies are missing
        return _skipped(wanted, f"the network lab cannot be imported: {exc}")
    ok, why = lab_available()
    if not ok:
        return _skipped(wanted, why)
    out: list[RowResult] = []
    ros_rows = [r for r in wanted if r != 9]  # row 6 too: the sync services re-run ros.master
    if shutil.which("roscore") is None:
        out += _skipped(ros_rows, "roscore is not installed (Debian package ros-core)")
        wanted = [r for r in wanted if r not in ros_rows]
    if 6 in wanted:
        from bench import sync_row

        ready, why = sync_row.available()
        if not ready:  # no lab needed to say so
            out.append(RowResult(6, TITLES[6], status="not available yet", reason=why))
            wanted.remove(6)
    if not wanted:
        return out
    funcs = {2: row2_full, 3: row3_bad_news, 6: row6_sync,
             9: lambda lab, opts, _state: deadlink_row.run(lab, opts, log)}
    lab = Lab()
    state = Path(tempfile.mkdtemp(prefix="rosnet-bench-state-"))
    global _COMPILED
    try:
        _COMPILED = compiled_copy(state / "package")
        log("lab: building")
        try:
            lab.build()
        except LabUnavailable as exc:
            return out + _skipped(wanted, str(exc))
        for r in wanted:
            log(f"row {r}: running")
            t0 = time.monotonic()
            try:
                res = funcs[r](lab, opts, state)
            except Exception as exc:
                res = RowResult(r, TITLES[r], status="error",
                                reason=f"{type(exc).__name__}: {exc}")
            res.seconds = time.monotonic() - t0
            out.append(res)
        if 2 in wanted and opts.quick:
            next(x for x in out if x.row == 2).lines.append(Line(
                2, "ROS 2 with mutual TLS, three sites: every seat's full verification (wall "
                   "time)", "s", status="skipped", note="not with --quick (it builds a "
                                                         "three-site lab)"))
        elif 2 in wanted:   # the three-site lab: its own namespaces, built after the two-site
            lab.destroy()
            t0 = time.monotonic()
            try:
                three = row2_three_sites(opts, state, log)
            except Exception as exc:
                three = RowResult(2, TITLES[2], status="error",
                                  reason=f"{type(exc).__name__}: {exc}")
            row2 = next(x for x in out if x.row == 2)
            row2.lines += three.lines
            row2.details.update(three.details)
            row2.seconds += time.monotonic() - t0
            if three.status != "measured":
                row2.lines.append(Line(2, "ROS 2 with mutual TLS, three sites: every seat's "
                                          "full verification (wall time)", "s",
                                       status=three.status, note=three.reason))
        for row2 in (x for x in out if x.row == 2):
            row2.lines.sort(key=lambda x: x.measure == COLD_MEASURE)
    finally:
        _COMPILED = None
        lab.destroy()
        shutil.rmtree(state, ignore_errors=True)
    return out
