"""The committed screenshots are what the real app draws today (regenerate: python -m rosnet_tui.screenshots)."""

from __future__ import annotations

from pathlib import Path

from rosnet_tui.screenshots import DEFAULT_OUT, generate


def test_committed_screenshots_match_the_app(tmp_path: Path):
    fresh = {p.name: p.read_text(encoding="utf-8") for p in generate(tmp_path)}
    committed = {p.name: p.read_text(encoding="utf-8") for p in DEFAULT_OUT.glob("*.svg")}
    assert sorted(committed) == sorted(fresh), "screenshots/ holds other files than the script makes"
    stale = [name for name in fresh if fresh[name] != committed[name]]
    assert not stale, f"stale screenshots {stale}: run `python -m rosnet_tui.screenshots`"
