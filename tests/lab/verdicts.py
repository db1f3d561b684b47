"""The lab tests' reading of `rosnet-tui check --json`: running it on a lab computer, one line a
check for an assertion's message, a check's own verdict within its bound, figures against the
shaping, and a settings file with a need for the link checks (ros.link, ros2.link)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rosnet_tui.core.config.settings_model import LinkTopic
from rosnet_tui.core.saved.settings import atomic_write_text, render_settings


def lab_check(lab: Any, host: str, *, step: str | None = None, config: Path | None = None,
              timeout: float = 90) -> dict[str, dict]:
    """`rosnet-tui check --json` on *host* (only *step* when given), in its ROS environment:
    {check id: its JSON entry}."""
    steps = ["--step", step] if step else []
    r = lab.rosnet(host, "check", "--json", *steps, "--config",
                   str(config or lab.config_path(host)), env=lab.ros_env(host), timeout=timeout)
    assert r.stdout.strip(), r.stderr
    return {c["id"]: c for c in json.loads(r.stdout)["checks"]}


def explain(results: dict[str, dict]) -> str:
    """Each check's status, time, summary, evidence and advice: an assertion's message."""
    return "\n".join(f"{c['id']}: {c['status']} ({c.get('duration_s', 0):.2f} s) - {c['summary']}"
                     + "".join(f"\n    {e}" for e in c["evidence"])
                     + "".join(f"\n  -> {a['meaning']}" for a in c.get("advice") or [])
                     for c in results.values())


def within(value: float | None, want: float, share: float) -> bool:
    """*value* measured and within *share* of *want*."""
    return value is not None and abs(value - want) <= want * share


def own_verdict(entry: dict, results: dict) -> None:
    """*entry* ended by itself within its budget, with a summary that is not the runner's."""
    assert entry["duration_s"] <= entry["timeout_s"] + 0.5, explain(results)
    assert not entry["summary"].startswith("no verdict within"), explain(results)
    assert "failed unexpectedly" not in entry["summary"], explain(results)
    assert entry["summary"], explain(results)
    assert entry["evidence"] or entry["status"] == "skip", explain(results)


def needing(settings: Any, home: Path, size: int, hz: float) -> Path:
    """A settings file in *home* of *settings* with one [[link.topic]] of *size* bytes at *hz*."""
    settings.link.topics = [LinkTopic("/camera/image/compressed", size, hz)]
    path = home / ".config" / "rosnet-tui" / "need.toml"
    atomic_write_text(path, render_settings(settings), mode=0o644)
    return path


def measured_unshaped(results: dict, link_id: str, peer: str) -> None:
    """*link_id* passed with the figures of the lab's unshaped path to *peer*: a round trip,
    over 10 Mbit/s each way, 1 MB delivered whole both ways."""
    link = results[link_id]
    assert link["status"] == "pass", explain(results)
    d = link["data"]["peers"][peer]
    assert d["rtt_ms"] is not None and d["out_bps"] > 10e6 and d["in_bps"] > 10e6, d
    assert d["largest_out"] == d["largest_in"] == 1 << 20, d
    assert "Mbit/s" in link["summary"] and " ms" in link["summary"], link["summary"]
    own_verdict(link, results)


def measured_delay(results: dict, link_id: str, base_ms: float, delay_ms: float) -> None:
    """*link_id*'s round trip to turtlebot is the lab's own (*base_ms*) plus a hop holding every
    chunk *delay_ms* each way, within 20 %; rates measured both ways; messages passing."""
    link = results[link_id]
    print(explain({link_id: link}))
    pubsub_in = link_id.split(".")[0] + ".pubsub_in"
    assert results[pubsub_in]["status"] == "pass", explain(results)
    d = link["data"]["peers"]["turtlebot"]
    assert within(d["rtt_ms"], 2 * delay_ms + base_ms, 0.2), explain(results)
    assert d["out_bps"] and d["in_bps"], explain(results)
    own_verdict(link, results)


def measured_thin(results: dict, link_id: str, rate_bps: float, share: float,
                  not_tried: str) -> dict:
    """*link_id* measured the robot's link shaped to *rate_bps* (within *share*) in its budget,
    1 MB not tried either way, and says that *not_tried* (a size up) was not, with why: the
    figures to turtlebot."""
    link = results[link_id]
    print(explain({link_id: link}))
    own_verdict(link, results)
    d = link["data"]["peers"]["turtlebot"]
    assert d["rtt_ms"] is not None, explain(results)
    assert within(d["out_bps"], rate_bps, share) and within(d["in_bps"], rate_bps, share), \
        explain(results)
    assert d["tried_out"] < 1 << 20 and d["tried_in"] < 1 << 20, explain(results)
    assert f"{not_tried} up not tried: about" in " ".join(link["evidence"]), explain(results)
    return d
