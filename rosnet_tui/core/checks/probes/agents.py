"""The round's peer agents on the master's side: which agent runs which program (ROS 1's on
the peer's python3, ROS 2's on the interpreter of the rosnet-tui installed there), and running
a program on one."""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path

from rosnet_tui.core.checks import CheckContext
from rosnet_tui.core.config.settings_model import Peer
from rosnet_tui.core.peer import (
    agentproto,
    chatproto,
    roslink,
    rosproto,
    tunnelproto,
    zenohlink,
    zenohproto,
)
from rosnet_tui.core.peer.commands import (
    NO_INSTALL_EXIT,
    NO_INSTALL_REPORT,
    installed_python_command,
    shq,
)
from rosnet_tui.core.peer.peer_agent import (
    AgentCall,
    AgentKind,
    PeerAgents,
    agent_run,
    agent_session,
)
from rosnet_tui.core.ssh.connection import SshResult

# One program per peer and round runs every probe the round's checks ask of that peer (see
# core/peer/peer_agent.py): ROS 1's on the peer's python3 without site (stdlib only), ROS 2's on the
# interpreter of the rosnet-tui installed there (eclipse-zenoh; paramiko for relay.tunnel's side).
# Both serve the Linux chats' peer side (core/peer/chatproto.py, stdlib). A peer without rosnet-tui
# gets ROS 2's agent on its python3 (the finder's fallback): what needs the install (the Zenoh
# probes: needs_install) answers with the finder's no_install report, as a lone command did.
ROSPROTO_SOURCE = Path(rosproto.__file__).read_bytes()   # the ROS 1 probe program
ZENOH_SOURCE = Path(zenohproto.__file__).read_bytes()    # the ROS 2 (Zenoh) probe program
CHAT_SOURCE = Path(chatproto.__file__).read_bytes()      # the chats' peer side
TUNNEL_SOURCE = Path(tunnelproto.__file__).read_bytes()  # relay.tunnel's peer side (paramiko)


def program_body(path: str, mark: str) -> bytes:
    """The source of a peer program loaded on another's names: the text of *path* from the
    second *mark* (the first defines it), under ``from __future__ import annotations``."""
    text, m = Path(path).read_bytes(), mark.encode()
    return b"from __future__ import annotations\n" + text[text.index(m, text.index(m) + 1):]


# ros2.link's and ros.link's peer sides: zenohlink's body on zenohproto's names (its imports
# there), roslink's on rosproto's
LINK_SOURCE = program_body(zenohlink.__file__, zenohlink.BODY_MARK)
ROSLINK_SOURCE = program_body(roslink.__file__, roslink.BODY_MARK)
PEER_PYTHON = "python3"   # the peer's python the ROS 1 agent and the chats run with


def peer_python() -> str:
    """The peer's python (the name, looked up on the peer's PATH)."""
    return PEER_PYTHON


ROS_AGENT = AgentKind(
    "ros1", lambda max_s: f"{peer_python()} -I -S -c {shq(agentproto.BOOT)} {max_s:.0f}",
    (("ros", ROSPROTO_SOURCE, "main"), ("rlink", ROSLINK_SOURCE, "run_link", "ros"),
     ("chat", CHAT_SOURCE, "main")))
ZENOH_AGENT = AgentKind(
    "ros2", lambda max_s: installed_python_command(f"{max_s:.0f}", mark=zenohproto.REPORT_MARK,
                                                   fallback=True, boot=agentproto.BOOT),
    (("zenoh", ZENOH_SOURCE, "run_program"), ("zlink", LINK_SOURCE, "run_link", "zenoh"),
     ("chat", CHAT_SOURCE, "main"), ("tunnel", TUNNEL_SOURCE, "main")),
    (f"{zenohproto.REPORT_MARK}{NO_INSTALL_REPORT}\n", NO_INSTALL_EXIT))


def chat_agent(ctx: CheckContext) -> AgentKind:
    """The agent that runs the chats' peer side in this round (its ROS version's)."""
    return ZENOH_AGENT if ctx.settings.ros2 else ROS_AGENT


def no_python(call: AgentCall | SshResult) -> bool:
    """The agent could not start for want of a python3 on the peer (exit status 127)."""
    return call.exit_status == 127 and not call.stdout


def _agents(ctx: CheckContext) -> PeerAgents:
    """The round's peer agents (run_checks closes them with the round)."""
    if ctx.peer_agents is None:
        ctx.peer_agents = PeerAgents()
    return ctx.peer_agents


def agent_life(ctx: CheckContext) -> float:
    """Seconds a peer agent may live at most (longer than any check of the round)."""
    return 60.0 + 10.0 * ctx.timeout_s


async def peer_run(ctx: CheckContext, peer: Peer, kind: AgentKind, program: str,
                   argv: Sequence[str], *, timeout: float, connect_timeout: float | None = None,
                   tcp_timeout: float | None = None, needs_install: bool = False,
                   source: bytes | None = None) -> SshResult:
    """Run *program* (one of *kind*'s, or with *source* one loaded on the agent when first
    run) with *argv* on *peer*'s agent of the round, as ``ssh_run`` would run it alone: the
    same bounds, the same result."""
    return await agent_run(_agents(ctx), ctx.ssh, peer, kind, program, argv, timeout=timeout,
                           connect_timeout=connect_timeout, tcp_timeout=tcp_timeout,
                           max_s=agent_life(ctx), needs_install=needs_install, source=source)


def peer_session(ctx: CheckContext, peer: Peer, kind: AgentKind, program: str,
                 argv: Sequence[str], *, timeout: float, tcp_timeout: float | None = None,
                 needs_install: bool = False, start_timeout: float | None = None
                 ) -> contextlib.AbstractAsyncContextManager[AgentCall]:
    """*program* running on *peer*'s agent for an ``async with`` block, read as ``ssh_session``'s
    session is (``ok``, ``result``, ``read_until``, ``wait``); *start_timeout*: how long this
    caller waits for the agent to start (default: see ``agent_call``)."""
    return agent_session(_agents(ctx), ctx.ssh, peer, kind, program, argv, timeout=timeout,
                         tcp_timeout=tcp_timeout, max_s=agent_life(ctx),
                         needs_install=needs_install, start_timeout=start_timeout)


def peer_program_problem(res: SshResult, peer: Peer) -> str | None:
    """Why a program could not run on *peer* over SSH (None when it ran)."""
    if res.failure:
        return f"SSH to {peer.name} failed ({res.failure}): {res.detail}"
    if res.exit_status == 127:
        return f"{peer.name} has no python3 to run the probe (exit status 127)"
    return None


def stderr_tail(res: SshResult) -> str:
    """The last lines the peer's program wrote on stderr, on one line."""
    tail = (res.stderr or "").strip().splitlines()[-3:]
    return " | ".join(tail)


def why_no_report(res: SshResult) -> str:
    """What a peer's program that gave no report left behind, on one line: its last lines on
    stderr, else the end of what it printed, else "no output"; then how it ended."""
    said = stderr_tail(res)
    if not said:
        out = (res.stdout or "").strip()
        said = f"its output ends {out[-80:]!r}" if out else "no output"
    return f"{said}; {res.detail}" if res.detail else said
