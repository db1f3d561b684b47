"""This component's public IP: read from this round's isp.public_ip, or asked of a service."""

from __future__ import annotations

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.checks.data import view
from rosnet_tui.core.exposure.public_ip import parse_ip
from rosnet_tui.core.net.http import http_get


def round_public_ip(ctx: CheckContext) -> str | None:
    """The public IP isp.public_ip found in this round (None: it did not run, or found none)."""
    res = ctx.results.get("isp.public_ip")
    if res is None:
        return None
    return view("isp.public_ip", res.data).get("public_ip")


async def fetch_public_ip(ctx: CheckContext, timeout: float) -> str | None:
    """This component's public IP: from this round's isp.public_ip if it ran, else one quick ask."""
    found = round_public_ip(ctx)
    if found:
        return str(found)
    for url in ctx.settings.probe.public_ip_urls[:1]:
        ans = await http_get(url, timeout)
        if ans.ok:
            return parse_ip(ans.text)
    return None
