"""SSH to a peer nobody can reach, with the relay as the jump host: two real sshd on 127.0.0.1
(the relay's and the component's), the component's reachable only through the reverse tunnel
that `rosnet-tui relay tunnel`'s keeper holds on the relay's loopback with OpenSSH's client."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import getpass
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import psutil
import pytest

from rosnet_tui.core.advisor import advise
from rosnet_tui.core.checks import REGISTRY, CheckContext, load_builtin_checks, run_check
from rosnet_tui.core.checks.linux import check_ssh
from rosnet_tui.core.checks.runner import RunOptions, make_context, prestart_ssh
from rosnet_tui.core.config.paths import Paths
from rosnet_tui.core.config.settings_model import (
    Peer,
    RelaySettings,
    RosSettings,
    Settings,
    ThisComponent,
)
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.results import Status
from rosnet_tui.core.ssh.client_config import preview_ssh_config
from rosnet_tui.core.ssh.options import SshOptions, relay_route
from rosnet_tui.core.ssh.pool import SshPool
from rosnet_tui.core.ssh.session import ssh_run
from rosnet_tui.core.ssh.sshd_keys import own_host_keys
from rosnet_tui.core.ssh.tunnel import TunnelKeeper, tunnel_argv
from rosnet_tui.core.ssh.tunnel_probe import probe_tunnel
from tests.builders import free_port
from tests.plugins.ssh import SSHD, Sshd, keygen

pytestmark = pytest.mark.skipif(not os.path.exists(SSHD) or not shutil.which("ssh"),
                                reason="needs OpenSSH (sshd, ssh, ssh-keygen)")

NAME = "turtlebot"      # the component behind the relay: its name resolves nowhere here


def wait_banner(port: int, within: float) -> bool:
    """Whether an SSH banner answers at 127.0.0.1:*port* within *within* seconds."""
    end = time.monotonic() + within
    while time.monotonic() < end:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5) as s:
                s.settimeout(0.5)
                if s.recv(64).startswith(b"SSH-"):
                    return True
        except OSError:
            pass
        time.sleep(0.05)
    return False


@dataclass
class Fleet:
    relay: Sshd
    robot: Sshd
    tunnel_port: int
    dot_ssh: Path            # the operator's side: its key, known_hosts for both hops
    tunnel_ssh: Path         # the robot's side: the tunnel's key and the relay's known_hosts
    user: str
    keeper: TunnelKeeper | None = None
    thread: threading.Thread | None = None
    said: list[str] = field(default_factory=list)

    def start_tunnel(self) -> None:
        opts = SshOptions(ssh_dir=self.tunnel_ssh, ssh_agent=False,
                          known_hosts_files=(self.tunnel_ssh / "known_hosts",))
        argv = tunnel_argv(self.relay_settings(), NAME, self.robot.port, opts)
        self.keeper = TunnelKeeper(argv, self.said.append)
        self.thread = threading.Thread(target=self.keeper.run, daemon=True)
        self.thread.start()

    def stop_tunnel(self) -> None:
        if self.keeper is not None and self.thread is not None:
            self.keeper.stop.set()
            self.thread.join(10)
            assert not self.thread.is_alive()

    def relay_settings(self, **kw) -> RelaySettings:
        kw.setdefault("host", "localhost")
        kw.setdefault("ssh_user", self.user)
        kw.setdefault("ssh_port", self.relay.port)
        kw.setdefault("tunnels", {NAME: self.tunnel_port})
        return RelaySettings(**kw)

    def opts(self, known_hosts: Path | None = None, **kw) -> SshOptions:
        return SshOptions(ssh_dir=self.dot_ssh, ssh_agent=False,
                          known_hosts_files=(known_hosts or self.dot_ssh / "known_hosts",),
                          relay=relay_route(self.relay_settings(**kw)))

    def peer(self) -> Peer:
        return Peer(name=NAME, ssh_user=self.user, ssh_port=22)

    def known_hosts(self, path: Path, relay_pub: str | None = None,
                    robot_pub: str | None = None, robot_as: str = NAME) -> Path:
        path.write_text(
            f"[localhost]:{self.relay.port} {(relay_pub or self.relay.host_pub).rsplit(' ', 1)[0]}\n"
            f"{robot_as} {(robot_pub or self.robot.host_pub).rsplit(' ', 1)[0]}\n")
        return path


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("jump")
    user = getpass.getuser()
    relay, robot = Sshd(root / "relay"), Sshd(root / "robot")
    dot_ssh = root / "dot_ssh"
    dot_ssh.mkdir(mode=0o700)
    op_pub = keygen(dot_ssh / "id_ed25519")
    tunnel_ssh = root / "tunnel_ssh"
    tunnel_ssh.mkdir(mode=0o700)
    t_pub = keygen(tunnel_ssh / "id_ed25519")
    port = free_port()
    # The relay's account: the tunnel's key may only listen at its port, the operator's key may
    # only open that port (docs/SECURITY.md's lines).
    relay.authorized.write_text(
        f'restrict,port-forwarding,permitlisten="127.0.0.1:{port}" {t_pub}\n'
        f'restrict,port-forwarding,permitopen="127.0.0.1:{port}" {op_pub}\n')
    robot.authorized.write_text(op_pub + "\n")
    relay.start()
    robot.start()
    (tunnel_ssh / "known_hosts").write_text(
        f"[localhost]:{relay.port} {relay.host_pub.rsplit(' ', 1)[0]}\n")
    f = Fleet(relay, robot, port, dot_ssh, tunnel_ssh, user)
    f.known_hosts(dot_ssh / "known_hosts")
    try:
        f.start_tunnel()
        assert wait_banner(port, 10), f"the reverse tunnel did not come up: {f.said}"
        yield f
    finally:
        f.stop_tunnel()
        relay.stop()
        robot.stop()


async def test_a_peer_with_a_tunnel_is_reached_through_the_relay(fleet):
    with pytest.raises(OSError):
        socket.getaddrinfo(NAME, 22)      # no direct way: the name does not even resolve
    res = await ssh_run(fleet.opts(), fleet.peer(), "echo through; cat", stdin="ok\n",
                        timeout=10)
    assert res.ok and res.exit_status == 0, res.detail
    assert res.stdout == "through\nok\n"
    assert res.fingerprint == fleet.robot.fingerprint       # the far host's key, not the relay's
    assert res.address is None            # its name was not resolved here


async def test_linux_ssh_and_the_pool_take_the_relay_from_the_settings(fleet):
    s = Settings(peers=[fleet.peer()], relay=fleet.relay_settings())
    pool = SshPool()
    ctx = CheckContext(settings=s, timeout_s=3.0, upnp=False, ssh_pool=pool,
                       ssh_options=SshOptions(ssh_dir=fleet.dot_ssh, ssh_agent=False,
                                              known_hosts_files=(fleet.dot_ssh / "known_hosts",)))
    try:
        out = await check_ssh(ctx)
        assert out.status == Status.PASS, out.evidence
        assert "through the relay localhost" in out.evidence[0]
        shared = await ssh_run(ctx.ssh, fleet.peer(), "echo again", timeout=10)
        assert shared.ok and shared.stdout == "again\n"
        assert len(pool._conns) == 1            # one connection through the relay, shared
    finally:
        pool.close()


async def test_a_round_prestarted_by_rosnet_tui_check_jumps_too(fleet, tmp_path):
    s = Settings(peers=[fleet.peer()], relay=fleet.relay_settings())
    o = RunOptions(timeout_s=3.0, upnp=False, paths=Paths(state_dir=tmp_path / "state",
                                                          bashrc_path=tmp_path / "bashrc"),
                   ssh=SshOptions(ssh_dir=fleet.dot_ssh, ssh_agent=False,
                                  known_hosts_files=(fleet.dot_ssh / "known_hosts",)))
    o = prestart_ssh(s, o)                # connects before the checks are even imported
    ctx = make_context(s, o)
    try:
        out = await check_ssh(ctx)
        assert out.status == Status.PASS, out.evidence
    finally:
        ctx.ssh_pool.close()


async def test_the_far_key_is_checked_under_the_component_s_name(fleet, tmp_path):
    # Known only under the address it is reached at on the relay: that is not its name.
    kh = fleet.known_hosts(tmp_path / "kh", robot_as=f"[127.0.0.1]:{fleet.tunnel_port}")
    res = await ssh_run(fleet.opts(kh), fleet.peer(), "echo no", timeout=10)
    assert res.failure == "host_key_unknown" and not res.stdout
    assert res.fingerprint == fleet.robot.fingerprint


async def test_a_changed_key_at_the_far_host_is_refused(fleet, tmp_path):
    other = keygen(tmp_path / "other")
    kh = fleet.known_hosts(tmp_path / "kh", robot_pub=other)
    res = await ssh_run(fleet.opts(kh), fleet.peer(), "echo no", timeout=10)
    assert res.failure == "host_key_changed" and not res.stdout
    assert "CHANGED" in res.detail


async def test_a_changed_key_at_the_relay_is_refused_before_any_login(fleet, tmp_path):
    other = keygen(tmp_path / "other")
    kh = fleet.known_hosts(tmp_path / "kh", relay_pub=other)
    before = fleet.relay.log.read_text()
    res = await ssh_run(fleet.opts(kh), fleet.peer(), "echo no", timeout=10)
    assert res.failure == "relay" and not res.stdout
    assert "CHANGED" in res.detail and "relay localhost" in res.detail
    assert res.host_key is None          # never offered for trust under the component's name
    assert "publickey" not in fleet.relay.log_until_ended(before)


async def test_an_unknown_relay_key_is_not_offered_as_the_component_s(fleet, tmp_path):
    kh = tmp_path / "kh"
    kh.write_text(f"{NAME} {fleet.robot.host_pub.rsplit(' ', 1)[0]}\n")
    res = await ssh_run(fleet.opts(kh), fleet.peer(), "echo no", timeout=10)
    assert res.failure == "relay" and "not in known_hosts" in res.detail
    assert res.host_key is None and res.fingerprint is None


async def test_a_tunnel_that_is_down_is_told_apart_from_the_relay(fleet):
    gone = free_port()
    t0 = time.monotonic()
    res = await ssh_run(fleet.opts(tunnels={NAME: gone}), fleet.peer(), "true", timeout=5)
    assert res.failure == "relay"     # the relay's account may open only the tunnel's port
    assert "does not let" in res.detail
    assert time.monotonic() - t0 < 5.5


async def test_a_silent_relay_gives_a_verdict_within_the_timeout(fleet):
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    try:
        t0 = time.monotonic()
        res = await ssh_run(fleet.opts(ssh_port=srv.getsockname()[1]), fleet.peer(), "true",
                            timeout=1.0)
        took = time.monotonic() - t0
    finally:
        srv.close()
    assert not res.ok and res.failure in ("relay", "timeout")
    assert took < 1.5


async def test_nothing_at_the_relay_is_a_relay_failure(fleet):
    res = await ssh_run(fleet.opts(ssh_port=free_port()), fleet.peer(), "true", timeout=3)
    assert res.failure == "relay" and "refused" in res.detail


def key_blob(pub: str) -> bytes:
    return base64.b64decode(pub.split()[1])


async def test_the_tunnel_probe_sees_this_machine_s_key_through_the_relay(fleet, tmp_path):
    route = relay_route(fleet.relay_settings())
    own = {key_blob(fleet.robot.host_pub)}
    st = await probe_tunnel(fleet.opts(), route, fleet.tunnel_port, own, 3.0)
    assert st.up and st.failure is None and st.fingerprint == fleet.robot.fingerprint
    other = await probe_tunnel(fleet.opts(), route, fleet.tunnel_port,
                               {key_blob(fleet.relay.host_pub)}, 3.0)
    assert not other.up and other.failure == "other_host"
    folder = tmp_path / "etc_ssh"
    folder.mkdir()
    (folder / "ssh_host_ed25519_key.pub").write_text(fleet.robot.host_pub + "\n")
    (folder / "ssh_host_rsa_key.pub").write_text("garbage\n")
    assert set(own_host_keys(folder).keys) == own


async def test_the_tunnel_probe_gives_bad_news_within_its_timeout(fleet):
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    try:
        route = relay_route(fleet.relay_settings(ssh_port=srv.getsockname()[1]))
        t0 = time.monotonic()
        st = await probe_tunnel(fleet.opts(), route, fleet.tunnel_port, set(), 1.0)
        took = time.monotonic() - t0
    finally:
        srv.close()
    assert not st.up and st.failure in ("relay", "timeout") and took < 1.5
    gone = relay_route(fleet.relay_settings(ssh_port=free_port()))
    st = await probe_tunnel(fleet.opts(), gone, fleet.tunnel_port, set(), 1.0)
    assert st.failure == "relay" and "refused" in st.detail


def tunnel_ctx(fleet, tmp_path, keys: str, timeout: float = 2.0) -> CheckContext:
    folder = tmp_path / "etc_ssh"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "ssh_host_ed25519_key.pub").write_text(keys + "\n")
    s = Settings(this=ThisComponent(name=NAME), ros=RosSettings(version=2),
                 relay=fleet.relay_settings())
    return CheckContext(settings=s, timeout_s=timeout, upnp=False,
                        paths=Paths(state_dir=tmp_path / "state", hosts_path=tmp_path / "hosts",
                                    bashrc_path=tmp_path / "bashrc", sshd_dir=folder),
                        ssh_options=SshOptions(ssh_dir=fleet.dot_ssh, ssh_agent=False,
                                               known_hosts_files=(fleet.dot_ssh / "known_hosts",)))


async def test_relay_tunnel_passes_when_the_port_leads_here(fleet, tmp_path):
    load_builtin_checks()
    res = await run_check(REGISTRY["relay.tunnel"], tunnel_ctx(fleet, tmp_path,
                                                                fleet.robot.host_pub))
    assert res.status == Status.PASS, res.evidence
    assert res.data["up"] is True and res.data["fingerprint"] == fleet.robot.fingerprint
    wrong = await run_check(REGISTRY["relay.tunnel"], tunnel_ctx(fleet, tmp_path / "w",
                                                                  fleet.relay.host_pub))
    assert wrong.status == Status.FAIL and wrong.data["failure"] == "other_host"
    elsewhere = tunnel_ctx(fleet, tmp_path / "x", fleet.robot.host_pub)
    elsewhere.settings.this.name = "sami"                 # no tunnel for this component
    skipped = await run_check(REGISTRY["relay.tunnel"], elsewhere)
    assert skipped.status == Status.SKIP


async def test_relay_tunnel_knows_an_sshd_that_keeps_its_keys_elsewhere(fleet, tmp_path):
    """The robot's sshd keeps its host key outside /etc/ssh (a HostKey line in its sshd_config,
    as every sshd of tests/plugins/ssh.py): relay.tunnel read only ssh_host_*_key.pub in the
    folder and warned that it could not tell whose sshd answers, though the tunnel was fine. It
    now takes the keys sshd takes, and its evidence names the files it compared."""
    load_builtin_checks()
    ctx = tunnel_ctx(fleet, tmp_path, fleet.robot.host_pub)
    ctx.paths = replace(ctx.paths, sshd_dir=fleet.robot.root)      # its sshd_config is there
    res = await run_check(REGISTRY["relay.tunnel"], ctx)
    assert res.status == Status.PASS, (res.summary, res.evidence)
    said = " ".join(res.evidence)
    assert f"{fleet.robot.host_key}.pub ({fleet.robot.fingerprint})" in said, said
    assert ("`sshd -T" if os.geteuid() == 0 else "HostKey lines") in said, said
    # Without sshd -T (not root): the same key from the HostKey line itself.
    read = own_host_keys(fleet.robot.root, ask_sshd=False)
    assert set(read.keys) == {key_blob(fleet.robot.host_pub)} and "HostKey lines" in read.source


async def test_relay_tunnel_bad_news_within_the_timeout(fleet, tmp_path):
    load_builtin_checks()
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    try:
        ctx = tunnel_ctx(fleet, tmp_path, fleet.robot.host_pub, timeout=1.0)
        ctx.settings.relay.ssh_port = srv.getsockname()[1]      # a relay that never answers
        t0 = time.monotonic()
        res = await run_check(REGISTRY["relay.tunnel"], ctx)
        took = time.monotonic() - t0
    finally:
        srv.close()
    assert res.status == Status.FAIL and took < 1.0 + 0.5, (took, res.summary)


def test_plain_ssh_reaches_the_component_through_the_config_block(fleet, tmp_path):
    cfg = tmp_path / "config"
    # The user's own lines: global ones first (they must keep applying to every host).
    mine = (f"IdentityFile {fleet.dot_ssh / 'id_ed25519'}\nIdentitiesOnly yes\n"
            f"UserKnownHostsFile {fleet.dot_ssh / 'known_hosts'}\n"
            "GlobalKnownHostsFile /dev/null\nBatchMode yes\nStrictHostKeyChecking yes\n"
            "Host *\n    ConnectTimeout 5\n")
    cfg.write_text(mine)
    cfg.chmod(0o600)                                   # OpenSSH refuses one others may write
    s = Settings(this=ThisComponent(name="sami"), peers=[fleet.peer()],
                 relay=fleet.relay_settings(tunnels={NAME: fleet.tunnel_port, "sami": 1}))
    preview = preview_ssh_config(s, cfg, state_dir=tmp_path / "state")
    assert preview is not None and "+Host turtlebot" in preview.diff()
    assert "Host sami" not in preview.diff()          # not a jump to itself
    mf.apply_preview(preview, state_dir=tmp_path / "state")
    text = cfg.read_text()
    assert text.endswith(mine) and text.startswith("# BEGIN rosnet-tui")
    assert (cfg.stat().st_mode & 0o777) == 0o600
    run = subprocess.run(["ssh", "-F", str(cfg), NAME, "echo via-openssh"], capture_output=True,
                         text=True, timeout=30, stdin=subprocess.DEVNULL)
    assert run.returncode == 0 and run.stdout == "via-openssh\n", run.stderr
    # The far key is checked under its name: a wrong one there is refused by OpenSSH too.
    kh = fleet.known_hosts(tmp_path / "kh", robot_pub=keygen(tmp_path / "other"))
    bad = subprocess.run(["ssh", "-F", str(cfg), "-o", f"UserKnownHostsFile={kh}", NAME, "true"],
                         capture_output=True, text=True, timeout=30, stdin=subprocess.DEVNULL)
    assert bad.returncode != 0 and "HOST IDENTIFICATION HAS CHANGED" in bad.stderr
    mf.undo_last(tmp_path / "state")
    assert cfg.read_text() == mine


def test_no_tunnel_to_jump_to_writes_nothing(fleet, tmp_path):
    s = Settings(this=ThisComponent(name=NAME), relay=fleet.relay_settings())
    assert preview_ssh_config(s, tmp_path / "config") is None
    assert preview_ssh_config(Settings(), tmp_path / "config") is None
    made = preview_ssh_config(Settings(peers=[fleet.peer()], relay=fleet.relay_settings()),
                              tmp_path / "config")
    assert made is not None and made.old is None and made.new_mode == 0o600


async def test_a_tunnel_killed_on_the_relay_is_back_within_10_s(fleet):
    assert fleet.keeper is not None and fleet.keeper.ups >= 1, fleet.said
    ups = fleet.keeper.ups
    relay_side = psutil.Process(fleet.relay.proc.pid).children(recursive=True)
    assert relay_side                   # the tunnel's session on the relay
    t0 = time.monotonic()
    for p in relay_side:
        with contextlib.suppress(psutil.Error):
            p.kill()
    while time.monotonic() - t0 < 10 and fleet.keeper.ups == ups:
        await asyncio.sleep(0.05)
    assert fleet.keeper.ups == ups + 1, fleet.said
    res = await ssh_run(fleet.opts(), fleet.peer(), "echo back", timeout=5)
    assert res.ok and res.stdout == "back\n", res.detail
    assert time.monotonic() - t0 < 10
    assert any(line.startswith("the tunnel dropped") for line in fleet.said), fleet.said


async def test_a_tunnel_that_is_down_says_so(fleet):
    fleet.stop_tunnel()
    assert fleet.said[-1] == "tunnel closed"
    end = time.monotonic() + 10
    while wait_banner(fleet.tunnel_port, 0.1) and time.monotonic() < end:
        time.sleep(0.05)
    res = await ssh_run(fleet.opts(), fleet.peer(), "true", timeout=5)
    assert res.failure == "network" and res.tcp == "refused"
    assert "tunnel is down" in res.detail and "relay tunnel" in res.detail
    ctx = CheckContext(settings=Settings(peers=[fleet.peer()], relay=fleet.relay_settings()),
                       timeout_s=3.0, upnp=False, ssh_options=fleet.opts())
    out = await check_ssh(ctx)
    assert out.status == Status.FAIL and "its tunnel on the relay is down" in out.summary
    assert "modem" not in out.summary
    st = await probe_tunnel(fleet.opts(), relay_route(fleet.relay_settings()), fleet.tunnel_port,
                            {key_blob(fleet.robot.host_pub)}, 3.0)
    assert not st.up and st.failure == "down"
    fleet.start_tunnel()


# --------------------------------------------------------------------------- the peer's side
def readme_like_install(home: Path) -> None:
    """rosnet-tui as pipx lays it out in *home*: a virtual environment whose Python has this
    one's packages (paramiko), its launcher in ~/.local/bin (the peer agent's install finder)."""
    v = home / ".local/share/pipx/venvs/rosnet-tui"
    v.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip",
                    str(v)], check=True, timeout=60)
    (v / "bin" / "rosnet-tui").write_text(f"#!{v}/bin/python\nimport sys\n")
    (v / "bin" / "rosnet-tui").chmod(0o755)
    (home / ".local/bin").mkdir(parents=True, exist_ok=True)
    (home / ".local/bin/rosnet-tui").symlink_to(v / "bin" / "rosnet-tui")


@dataclass
class PeerSide:
    sshd: Sshd               # the peer (sami): its sshd, where the check runs its side
    home: Path               # the peer user's home there: its keys, its known_hosts
    known_hosts: Path        # ours: the relay, the component and the peer

    def trust_relay(self, fleet: Fleet, yes: bool = True) -> None:
        line = f"[localhost]:{fleet.relay.port} {fleet.relay.host_pub.rsplit(' ', 1)[0]}\n"
        (self.home / ".ssh" / "known_hosts").write_text(line if yes else "")


@pytest.fixture(scope="module")
def peer_side(fleet, tmp_path_factory):
    root = tmp_path_factory.mktemp("peer")
    home = root / "home"
    (home / ".ssh").mkdir(parents=True, mode=0o700)
    readme_like_install(home)
    pub = keygen(home / ".ssh" / "id_ed25519")
    sshd = Sshd(root / "sshd", extra_config=f"SetEnv HOME={home}\n")
    sshd.authorized.write_text((fleet.dot_ssh / "id_ed25519.pub").read_text())
    with fleet.relay.authorized.open("a") as f:   # the peer's key may open the tunnel's port
        f.write(f'restrict,port-forwarding,permitopen="127.0.0.1:{fleet.tunnel_port}" {pub}\n')
    known = root / "known_hosts"
    fleet.known_hosts(known)
    with known.open("a") as f:
        f.write(f"[localhost]:{sshd.port} {sshd.host_pub.rsplit(' ', 1)[0]}\n")
    side = PeerSide(sshd, home, known)
    side.trust_relay(fleet)
    sshd.start()
    try:
        yield side
    finally:
        sshd.stop()


def peer_ctx(fleet, side: PeerSide, tmp_path: Path, timeout: float = 3.0) -> CheckContext:
    ctx = tunnel_ctx(fleet, tmp_path, fleet.robot.host_pub, timeout)
    ctx.settings.peers = [Peer(name="localhost", ssh_user=fleet.user, ssh_port=side.sshd.port)]
    ctx.ssh_options = replace(ctx.ssh_options, known_hosts_files=(side.known_hosts,))
    return ctx


async def test_relay_tunnel_is_asked_from_the_peer_s_side_too(fleet, peer_side, tmp_path):
    """The peer logs in to the relay with its own key and its own known_hosts, and finds this
    machine's sshd at the tunnel's port: a pass naming it. The relay's key unknown to the peer:
    the tunnel is up from here, and still a failure, since that peer cannot SSH here."""
    load_builtin_checks()
    assert wait_banner(fleet.tunnel_port, 10), fleet.said
    res = await run_check(REGISTRY["relay.tunnel"], peer_ctx(fleet, peer_side, tmp_path))
    assert res.status == Status.PASS, (res.summary, res.evidence)
    seen = res.data["peers"]["localhost"]
    assert seen["up"] is True and seen["fingerprint"] == fleet.robot.fingerprint, seen
    assert "localhost reaches it through the relay" in res.summary
    peer_side.trust_relay(fleet, yes=False)
    try:
        res = await run_check(REGISTRY["relay.tunnel"], peer_ctx(fleet, peer_side,
                                                                  tmp_path / "b"))
    finally:
        peer_side.trust_relay(fleet)
    assert res.status == Status.FAIL and res.data["up"] is True, res.summary
    assert res.data["failure"] == "peer" and res.data["peers"]["localhost"]["failure"] == "relay"
    assert "localhost cannot reach this machine through it" in res.summary
    results = {"relay.tunnel": res}
    f = next(f for f in advise(results, res_settings(fleet), strict=True)
             if f.rule == "relay.tunnel.down")
    assert "On localhost: run `ssh" in f.actions[0] and "permitopen" in f.actions[0]


async def test_a_peer_s_side_that_cannot_run_is_a_warning_not_a_pass(fleet, peer_side, tmp_path):
    """No SSH to the peer (its host key unknown here): the tunnel is up from here, but nobody
    looked from a peer's side, within the check's budget."""
    load_builtin_checks()
    ctx = peer_ctx(fleet, peer_side, tmp_path, timeout=1.5)
    ctx.ssh_options = replace(ctx.ssh_options, known_hosts_files=(fleet.dot_ssh / "known_hosts",))
    t0 = time.monotonic()
    res = await run_check(REGISTRY["relay.tunnel"], ctx)
    assert time.monotonic() - t0 < 1.5 * 2.0 + 0.5
    assert res.status == Status.WARN and res.data["peers"]["localhost"]["up"] is None, res.summary
    assert "no peer could test it from its side" in res.summary


def res_settings(fleet) -> Settings:
    return Settings(this=ThisComponent(name=NAME), ros=RosSettings(version=2),
                    relay=fleet.relay_settings())
