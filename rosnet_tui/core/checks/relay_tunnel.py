"""relay.tunnel (ROS 2 with a relay, Linux step): this component's reverse tunnel on the relay
is up, asked through the relay as a peer reaches it: the relay's 127.0.0.1:<port> answers with
this machine's own sshd host key (:mod:`rosnet_tui.core.ssh.tunnel_probe`)."""

from __future__ import annotations

from typing import Any

from rosnet_tui.core.checks import CheckContext, check
from rosnet_tui.core.results import Outcome, Status
from rosnet_tui.core.ssh.options import relay_route
from rosnet_tui.core.ssh.tunnel_probe import own_host_keys, probe_tunnel

WHY = {
    "down": "nothing answers there: `rosnet-tui relay tunnel` is not running here, or its "
            "link is down",
    "other_host": "another sshd answers there (another component's tunnel on the same port, or "
                  "a stale session on the relay)",
    "not_sshd": "something that is not sshd answers there",
    "relay": "the relay itself cannot be used",
    "timeout": "no answer in time",
}


@check("relay.tunnel", "linux", "This component's SSH tunnel answers on the relay", 1.5, ros=2,
       switch="relay")
async def check_relay_tunnel(ctx: CheckContext) -> Outcome:
    s = ctx.settings
    route = relay_route(s.relay)
    port = route.tunnel_port(s.this.name) if route is not None else None
    if route is None or port is None:
        return Outcome(Status.SKIP, f"no tunnel for {s.this.name or 'this component'} under "
                                    "[relay.tunnels]: its peers reach it directly")
    data: dict[str, Any] = {"relay": route.host, "port": port}
    own = own_host_keys(ctx.paths.sshd_dir)
    if not own:
        data.update(up=None, failure="own_keys")
        return Outcome(Status.WARN, f"this machine's sshd host keys are not readable in "
                                    f"{ctx.paths.sshd_dir}: whose sshd answers on the relay "
                                    "cannot be told", data=data)
    st = await probe_tunnel(ctx.ssh, route, port, own, ctx.timeout_s)
    data.update(up=st.up, failure=st.failure, fingerprint=st.fingerprint, detail=st.detail)
    evidence = [f"ssh {route.user}@{route.host}, then 127.0.0.1:{port} there: {st.detail}"]
    if st.up:
        return Outcome(Status.PASS, f"the relay {route.host} leads to this machine's sshd at "
                                    f"127.0.0.1:{port}", evidence, data)
    return Outcome(Status.FAIL, f"the tunnel at 127.0.0.1:{port} on {route.host} does not reach "
                                f"this machine: {WHY.get(st.failure or '', st.detail)}",
                   evidence, data)
