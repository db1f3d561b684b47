"""A check's time budget: its timeout times its factor."""

from __future__ import annotations

from rosnet_tui.core.checks import REGISTRY, CheckContext


def budget(ctx: CheckContext, check_id: str) -> float:
    """Seconds *check_id* may take under *ctx* (its timeout times its factor)."""
    spec = REGISTRY.get(check_id)
    return ctx.timeout_s * (spec.timeout_factor if spec else 1.0)
