"""What the checks of several steps share: time budgets, this round's public IP, and small
stdlib-only programs run on a peer over SSH (HTTP: :mod:`rosnet_tui.core.http`).

The check modules (``isp``, ``router``, ``linux``, ``ros``) import from here and from the core,
never from each other, so each step's checks can change without opening another step's file.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import shlex
import sys
from collections.abc import Awaitable, Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

from rosnet_tui.core import agentproto, chatproto, fleet_tls, ros2, rosproto, zenohproto
from rosnet_tui.core.checks import REGISTRY, CheckContext
from rosnet_tui.core.checks.data import view
from rosnet_tui.core.http import http_get
from rosnet_tui.core.peer_agent import AgentCall, AgentKind, PeerAgents, agent_run, agent_session
from rosnet_tui.core.public_ip import parse_ip
from rosnet_tui.core.settings_model import Peer, Settings
from rosnet_tui.core.ssh.connection import SshResult, run_blocking

T = TypeVar("T")


def budget(ctx: CheckContext, check_id: str) -> float:
    """Seconds *check_id* may take under *ctx* (its timeout times its factor)."""
    spec = REGISTRY.get(check_id)
    return ctx.timeout_s * (spec.timeout_factor if spec else 1.0)


# --------------------------------------------------------------------------- the public IP
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


# --------------------------------------------------------------------------- programs on a peer
def ssh_peers(s: Settings) -> list[Peer]:
    """The peers we can run commands on (those with an SSH user), in the settings' order."""
    return [p for p in s.peers if p.ssh_user]


NO_SSH_USER = ("no peer has an SSH user in the settings (peer.ssh_user), so the peer's side cannot "
               "be run from here")

PEER_CONCURRENCY = 8  # peers one check works with at once (the largest fleet: 8 members)


async def each_peer(peers: Sequence[Peer], work: Callable[[Peer], Awaitable[T]], *,
                    limit: int = PEER_CONCURRENCY, return_exceptions: bool = False
                    ) -> list[T | BaseException]:
    """``await work(peer)`` for every peer, concurrently, at most *limit* at once (each peer's
    SSH sessions share its one connection of the round); results in *peers*' order. With
    *return_exceptions*, an exception is that peer's result, as with ``asyncio.gather``."""
    gate = asyncio.Semaphore(max(1, limit))

    async def one(peer: Peer) -> T:
        async with gate:
            return await work(peer)

    return await asyncio.gather(*(one(p) for p in peers), return_exceptions=return_exceptions)


def shq(s: str) -> str:
    """*s* quoted for a POSIX shell (single quotes)."""
    return "'" + s.replace("'", "'\\''") + "'"


def python_command(script: str, *args: str, python: str = "python3") -> str:
    """A shell command running stdlib-only *script* with python3 on a peer (no install needed).

    ``-S``: the probes need the standard library only, so the peer skips site (its
    site-packages, .pth files): a faster start, and nothing of the peer's can shadow a module.
    """
    b64 = base64.b64encode(script.encode()).decode()
    quoted = " ".join(shq(a) for a in args)
    return (f"{python} -S -c 'import base64;exec(base64.b64decode(\"{b64}\"))' "
            f"{quoted}").strip()


def python_stdin_command(*args: str) -> str:
    """A shell command running the stdlib-only program fed on stdin with python3 on a peer
    (``python3 -S -``: without site, as :func:`python_command`)."""
    return "python3 -S - " + " ".join(shlex.quote(a) for a in args)


# The README installs rosnet-tui (with eclipse-zenoh) in a virtual environment of its own; the
# peer's python3 has no eclipse-zenoh (and under PEP 668 pip may not add it). So the Zenoh peer
# program runs with the interpreter of the rosnet-tui installed on the peer, found by this POSIX
# sh prelude in the same SSH round trip: the launchers the README's installs make (pipx, uv tool,
# the root-owned pipx), their virtual environments, the PATH, and last a login shell's PATH
# (bounded by `timeout`: fixed places first). A launcher's interpreter is its first line, or the
# path on its second line in the `#!/bin/sh` form pip and uv write for long paths, or else the
# `python` beside the launcher's target. The program is still fed on stdin, so the version of
# the peer's rosnet-tui does not matter. Nothing here reads stdin: the program must arrive whole.
NO_INSTALL_EXIT = 4       # the prelude's exit status when no rosnet-tui is installed on the peer
PEER_INSTALL_PLACES = ("the PATH, ~/.local/bin, pipx's and uv's tool folders, /usr/local/bin, "
                       "/opt/pipx, a login shell's PATH")
README_INSTALL = "sudo apt install -y --no-install-recommends pipx && pipx install --force ."
"""The README's install line without its last part (opening the wizard), typed in a checkout."""
_FIND_INSTALL = r"""
py=; h=${HOME:-~}; d=${XDG_DATA_HOME:-$h/.local/share}
L() {
  [ -f "$1" ] || return 1
  l1=; l2=; { IFS= read -r l1; IFS= read -r l2; } <"$1" 2>/dev/null
  case $l1 in
  "#!/bin/sh"*) r=${l2#*"exec' "}; q=${r%"${r#?}"}; r=${r#?}; p=${r%%"$q"*} ;;
  "#!"*) r=${l1#??}; r=${r#"${r%%[! ]*}"}; p=${r%% *} ;;
  *) p= ;;
  esac
  case $p in */env|*/sh|*/bash) p= ;; /*) ;; *) p= ;; esac
  [ -n "$p" ] && [ -x "$p" ] || p=$(dirname -- "$(readlink -f -- "$1")")/python
  [ -x "$p" ] && py=$p
}
V() { [ -x "$1/rosnet-tui/bin/python" ] && py=$1/rosnet-tui/bin/python; }
for b in "${PIPX_BIN_DIR:-$h/.local/bin}" "${UV_TOOL_BIN_DIR:-${XDG_BIN_HOME:-$h/.local/bin}}"; do
  [ -n "$py" ] || L "$b/rosnet-tui"
done
for v in "${PIPX_HOME:-$d/pipx}/venvs" "$h/.local/pipx/venvs" "${UV_TOOL_DIR:-$d/uv/tools}"; do
  [ -n "$py" ] || V "$v"
done
[ -n "$py" ] || { b=$(command -v rosnet-tui) && L "$b"; }
[ -n "$py" ] || L /usr/local/bin/rosnet-tui || V /opt/pipx/venvs
[ -n "$py" ] || { b=$(timeout 3 "${SHELL:-/bin/sh}" -lc "command -v rosnet-tui" </dev/null \
                     2>/dev/null | tail -n 1) && L "$b"; }
[ -n "$py" ] && [ -n "$BOOT" ] && exec "$py" -c "$BOOT" "$@"
[ -n "$py" ] && exec "$py" - "$@"
[ -n "$FALLBACK" ] && [ -n "$BOOT" ] && exec python3 -S -c "$BOOT" "$@" no-install
[ -n "$FALLBACK" ] && exec python3 -S - "$@"
echo "$MARK$NO_INSTALL"
exit @EXIT@
""".replace("@EXIT@", str(NO_INSTALL_EXIT))
NO_INSTALL_REPORT = '{"error": "no_install", "detail": "no rosnet-tui installed"}'
"""What a peer without rosnet-tui installed reports (after the program's mark)."""


def installed_python_command(*args: str, mark: str, fallback: bool = False,
                             boot: str | None = None) -> str:
    """The command running a program fed on stdin on a peer with the interpreter of the
    rosnet-tui installed there (its packages: eclipse-zenoh, paramiko, cryptography), found by
    _FIND_INSTALL; one SSH round trip. Without an installation it prints ``<mark>{"error":
    "no_install", ...}`` and exits NO_INSTALL_EXIT, unless *fallback* (a program that also runs
    on the standard library alone: the peer's python3 runs it then). Run by ``sh -c``, so the
    peer's login shell may be any shell. Never the peer's python3 for a program that needs the
    install's packages. With *boot*, the interpreter runs ``-c boot`` (a loader that reads the
    program from stdin and leaves stdin open: the peer agent's) instead of ``-``."""
    script = ("MARK=" + shq(mark) + "\nNO_INSTALL=" + shq(NO_INSTALL_REPORT) + "\n"
              + ("FALLBACK=1\n" if fallback else "")
              + ("BOOT=" + shq(boot) + "\n" if boot else "") + _FIND_INSTALL)
    return "sh -c " + shq(script) + " rosnet-tui-peer " + " ".join(shq(a) for a in args)


def zenoh_peer_command(*args: str, need_zenoh: bool = True) -> str:
    """The command running the Zenoh peer program (core/zenohproto.py, fed on stdin) on a peer
    with the interpreter of the rosnet-tui installed there (:func:`installed_python_command`).
    Without an installation it prints a ``no_install`` report and exits NO_INSTALL_EXIT, unless
    not *need_zenoh* (``info`` needs only the standard library: the peer's python3 runs it
    then)."""
    return installed_python_command(*args, mark=zenohproto.REPORT_MARK, fallback=not need_zenoh)


# --------------------------------------------------------------------------- the round's peer agents
# One program per peer and round runs every probe the round's checks ask of that peer (see
# core/peer_agent.py): ROS 1's on the peer's python3 without site (stdlib only), ROS 2's on the
# interpreter of the rosnet-tui installed there (eclipse-zenoh).
# Both serve the Linux chats' peer side (core/chatproto.py, stdlib). A peer without rosnet-tui
# gets ROS 2's agent on its python3 (the finder's fallback): what needs the install (the Zenoh
# probes: needs_install) answers with the finder's no_install report, as a lone command did.
ROSPROTO_SOURCE = Path(rosproto.__file__).read_bytes()   # the ROS 1 probe program
ZENOH_SOURCE = Path(zenohproto.__file__).read_bytes()    # the ROS 2 (Zenoh) probe program
CHAT_SOURCE = Path(chatproto.__file__).read_bytes()      # the chats' peer side
PEER_PYTHON = "python3"   # the peer's python the ROS 1 agent and the chats run with


def peer_python() -> str:
    """The peer's python (the name, looked up on the peer's PATH)."""
    return PEER_PYTHON


ROS_AGENT = AgentKind(
    "ros1", lambda max_s: f"{peer_python()} -S -c {shq(agentproto.BOOT)} {max_s:.0f}",
    (("ros", ROSPROTO_SOURCE, "main"), ("chat", CHAT_SOURCE, "main")))
ZENOH_AGENT = AgentKind(
    "ros2", lambda max_s: installed_python_command(f"{max_s:.0f}", mark=zenohproto.REPORT_MARK,
                                                   fallback=True, boot=agentproto.BOOT),
    (("zenoh", ZENOH_SOURCE, "run_program"), ("chat", CHAT_SOURCE, "main")),
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
                   tcp_timeout: float | None = None, needs_install: bool = False) -> SshResult:
    """Run *program* (one of *kind*'s) with *argv* on *peer*'s agent of the round, as
    ``ssh_run`` would run it alone: the same bounds, the same result."""
    return await agent_run(_agents(ctx), ctx.ssh, peer, kind, program, argv, timeout=timeout,
                           connect_timeout=connect_timeout, tcp_timeout=tcp_timeout,
                           max_s=agent_life(ctx), needs_install=needs_install)


def peer_session(ctx: CheckContext, peer: Peer, kind: AgentKind, program: str,
                 argv: Sequence[str], *, timeout: float, tcp_timeout: float | None = None,
                 needs_install: bool = False
                 ) -> contextlib.AbstractAsyncContextManager[AgentCall]:
    """*program* running on *peer*'s agent for an ``async with`` block, read as ``ssh_session``'s
    session is (``ok``, ``result``, ``read_until``, ``wait``)."""
    return agent_session(_agents(ctx), ctx.ssh, peer, kind, program, argv, timeout=timeout,
                         tcp_timeout=tcp_timeout, max_s=agent_life(ctx),
                         needs_install=needs_install)


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


# --------------------------------------------------------------------------- ROS 2 (rmw_zenoh)
# Shared by the ros2.* checks (checks/ros2.py and checks/ros2_graph.py).


def zenoh_env(ctx: CheckContext) -> dict[str, str]:
    """The ROS 2 variables nodes started here get (environment, then ~/.bashrc)."""
    return zenohproto.ros_env(ctx.env, str(ctx.paths.bashrc_path))


def node_domain(ctx: CheckContext) -> int:
    """The ROS_DOMAIN_ID nodes started here use (unset: 0); ros2.env compares it with the settings."""
    value = zenoh_env(ctx).get("ROS_DOMAIN_ID", "").strip() or "0"
    return int(value) if value.isdigit() else ctx.settings.ros.domain_id


def node_endpoint(ctx: CheckContext) -> tuple[str, str]:
    """(endpoint, 'router'|'client'): where a ROS 2 node started here connects."""
    return zenohproto.peer_endpoint(zenoh_env(ctx), ros2.local_endpoint())


def client_tls() -> dict[str, Any]:
    """How a check dials a ``tls/`` endpoint: with this component's fleet key and certificate,
    trusting the fleet CA, the name in the locator verified (ROS 2 mutual TLS)."""
    p = fleet_tls.tls_paths(ros2.config_dir())
    return {"root_ca_certificate": str(p.ca_crt), "connect_private_key": str(p.node_key),
            "connect_certificate": str(p.node_crt), "enable_mtls": True,
            "verify_name_on_connect": True}


async def open_zenoh(endpoint: str, t: float, how: str = "client"
                     ) -> tuple[Any | None, str | None]:
    """A Zenoh session on *endpoint* within *t* s: (session, None) or (None, why not). *how* is
    node_endpoint()'s answer (a node's way in: a peer of a router, or client), or "client".
    A ``tls/`` endpoint is dialled with this component's fleet certificate (client_tls)."""
    mode = zenohproto.session_mode(how)
    tls = client_tls() if endpoint.startswith("tls/") else None
    try:
        return await run_blocking(zenohproto.open_client, endpoint, t, mode, tls,
                                  timeout=t + 0.4), None
    except asyncio.TimeoutError:
        return None, f"no Zenoh session within {t + 0.4:.1f} s"
    except zenohproto.ZenohMissing:
        return None, (f"eclipse-zenoh is not installed for this Python ({sys.executable}); it "
                      f"comes with rosnet-tui: reinstall it as the README says (`{README_INSTALL}`)")
    except zenohproto.OpenFailed as exc:
        return None, str(exc)


async def close_zenoh(session: Any) -> None:
    if session is not None:
        with contextlib.suppress(Exception):
            await run_blocking(session.close, timeout=1.0)


def ros2_peers(ctx: CheckContext) -> list[Peer]:
    """Peers to run the other side on (those with an SSH user), the master first."""
    s = ctx.settings
    return sorted(ssh_peers(s), key=lambda p: p.name != s.master_name)


def zenoh_peer_problem(res: SshResult, peer: Peer, rep: dict | None) -> str | None:
    """Why the peer's zenoh program gave no usable report (None: it did)."""
    if res.failure and res.failure != "timeout" and rep is None:
        return f"SSH to {peer.name} failed ({res.failure}): {res.detail}"
    if rep is not None and rep.get("error") == "no_install":
        return (f"rosnet-tui is not installed on {peer.name} (looked in {PEER_INSTALL_PLACES}): "
                f"install it there as the README says, in a checkout: `{README_INSTALL}`")
    if res.exit_status == 127:
        return f"{peer.name} has no sh or python3 to run the probe (exit status 127)"
    if rep is not None and rep.get("error") == "no_zenoh":
        return (f"the rosnet-tui on {peer.name} ({rep.get('python') or 'its Python'}) has no "
                f"eclipse-zenoh: reinstall it there as the README says, in a checkout: "
                f"`{README_INSTALL}`")
    if rep is None:
        return (f"the probe on {peer.name} gave no report "
                f"({stderr_tail(res) or res.detail or 'no output'})")
    return None


def router_links(info: dict) -> list[str]:
    """Ids of the routers a router (its admin space *info*) has sessions with."""
    return [x["zid"] for x in info.get("sessions") or [] if x.get("whatami") == "router"]
