"""The peers-only firewall (`rosnet-tui firewall`) on a lab computer, as the product sets it up
for ROS 1: load it before a test that wants every check to pass, remove it afterwards."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path


def apply_firewall(lab, host: str, config: Path) -> None:
    """`rosnet-tui firewall apply --yes` on *host* (lab or fleet), its journal in a scratch dir."""
    state = lab.home(host) / ".firewall-state"
    r = lab.rosnet(host, "firewall", "apply", "--yes", "--no-checks", "--config", str(config),
                   "--state-dir", str(state), timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr
    # The undo it prints is the one that finds this journal (issue 29, section 4, row 10).
    undo = next(x for x in r.stdout.splitlines() if "Undo with: " in x).split("Undo with: ")[1]
    assert f"--state-dir {state}" in undo and f"--config {config}" in undo, undo


def remove_firewall(lab, host: str) -> None:
    """Delete our table on *host*, if any (nothing else is touched)."""
    lab.run(host, ["nft", "delete", "table", "inet", "rosnet_tui"], timeout=10)


@contextlib.contextmanager
def secured(lab, hosts=None, config=None) -> Iterator[None]:
    """ROS 1's default security on *hosts* (default: every computer of *lab*): the peers-only
    firewall loaded (config(host) gives a host's settings file; default lab.config_path), removed
    afterwards. rosnet-tui is installed already (Lab.reset, Fleet, Ros2World)."""
    hosts = list(lab.COMPUTERS if hosts is None else hosts)
    config = config or lab.config_path
    try:
        for h in hosts:
            apply_firewall(lab, h, config(h))
        yield
    finally:
        for h in hosts:
            remove_firewall(lab, h)
