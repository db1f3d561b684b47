"""The peers-only firewall (`rosnet-tui firewall`) on a lab computer, as the product sets it up
for ROS 1: load it before a test that wants every check to pass, remove it afterwards."""

from __future__ import annotations

from pathlib import Path


def apply_firewall(lab, host: str, config: Path) -> None:
    """`rosnet-tui firewall apply --yes` on *host* (lab or fleet), its journal in a scratch dir."""
    r = lab.rosnet(host, "firewall", "apply", "--yes", "--no-checks", "--config", str(config),
                   "--state-dir", str(lab.home(host) / ".firewall-state"), timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr


def remove_firewall(lab, host: str) -> None:
    """Delete our table on *host*, if any (nothing else is touched)."""
    lab.run(host, ["nft", "delete", "table", "inet", "rosnet_tui"], timeout=10)
