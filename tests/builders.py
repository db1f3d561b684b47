"""One home for what the tests build: settings, check results, free ports.

The settings are the project's standard cast: turtlebot (the robot, ROS master, behind a telecom
router) and sami (a laptop behind its home modem), with addresses from the documentation ranges.
Result builders follow the checks contract (check ids and their ``data`` keys).
"""

from __future__ import annotations

import random
import socket
from dataclasses import replace
from pathlib import Path

from rosnet_tui.core.config.settings_model import (
    CheckSettings,
    Peer,
    ProbeSettings,
    RosSettings,
    Settings,
    SyncSettings,
    ThisComponent,
)
from rosnet_tui.core.net.netinfo import LocalNet
from rosnet_tui.core.results import CheckResult, Status

# The robot's settings file as a person writes it (the CLI tests hand it to --config).
ROBOT_CONFIG = """\
# my robot
[this]
name = "turtlebot"
role = "master"
connection = "telecom"
profile = "remote"
local_ip = "10.10.10.1"
public_ip = "203.0.113.2"
office_ip = "172.16.0.5"

[[peer]]
name = "sami"
local_ip = "192.168.1.10"
public_ip = "198.51.100.2"
office_ip = "172.16.0.6"

[ros]
master = "turtlebot"
port = 11311
"""


def random_hosts(n_bytes: int, seed: int) -> bytes:
    """Hosts lines (10/8 addresses, names) of at least *n_bytes*: the same for a seed, other
    lines for another seed (a big hosts file to write, cut and restore)."""
    rng = random.Random(seed)
    lines, size = [], 0
    while size < n_bytes:
        line = f"10.{rng.randrange(256)}.{rng.randrange(256)}.{rng.randrange(1, 255)}\t" \
               f"host-{seed}-{len(lines)}.example\thost-{len(lines)}\n"
        lines.append(line)
        size += len(line)
    return "".join(lines).encode()


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on *host* right now (the kernel's pick)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def loopback_master_config(folder: Path, ip_url: str, probe_url: str, *,
                           ros_port: int | None = None, timeout_s: float = 2.0,
                           keep_warm_s: float | None = None) -> Path:
    """folder/config.toml: a ROS 1 master of its own, with no peers, whose what-is-my-IP and
    port-check services are *ip_url* and *probe_url* (on loopback: `rosnet-tui check` as a user
    runs it, with nothing leaving this machine)."""
    warm = "" if keep_warm_s is None else f"keep_warm_s = {keep_warm_s}\n"
    cfg = folder / "config.toml"
    cfg.write_text(f"""
[this]
name = "turtlebot"
role = "master"
connection = "home"
profile = "remote"

[ros]
master = "turtlebot"
port = {ros_port or free_port()}

[probe]
port = {free_port()}
public_ip_urls = ["{ip_url}"]
port_check_url = "{probe_url}"

[checks]
timeout_s = {timeout_s}
{warm}""")
    return cfg


# --------------------------------------------------------------------------- whole settings
def checked_settings(this: ThisComponent, peers: list[Peer], master: str, *, probe_port: int,
                     public_ip_url: str, port_check_url: str, timeout_s: float = 3.0
                     ) -> Settings:
    """Settings every check can run with: ROS 1 with *master* on 11311, the probe (its test
    port, what-is-my-IP and port-check URLs) and the checks' timeout (the lab's and the
    bench's)."""
    return Settings(this=this, peers=peers, ros=RosSettings(master=master, port=11311),
                    probe=ProbeSettings(port=probe_port, public_ip_urls=[public_ip_url],
                                        port_check_url=port_check_url),
                    checks=CheckSettings(timeout_s=timeout_s))


# --------------------------------------------------------------------------- results
def result(cid: str, status: str = "pass", summary: str = "", data: dict | None = None, *,
           step: str | None = None, evidence: list[str] | None = None, elapsed: float = 0.1,
           timeout: float = 3.0) -> CheckResult:
    """A check result as a check reports it (its step is the id's first part by default)."""
    return CheckResult(cid, step or cid.split(".")[0], Status(status), summary,
                       [] if evidence is None else evidence, elapsed, timeout, dict(data or {}))


# --------------------------------------------------------------------------- the advisor's cast
CAST = {"turtlebot": dict(role="master", connection="telecom", local_ip="10.10.10.1",
                         public_ip="203.0.113.2"),
        "sami": dict(role="member", connection="home", local_ip="192.168.1.10",
                     public_ip="198.51.100.2")}


def _seat(who: str, peer: str, /, **this) -> Settings:
    """*who*'s settings (CAST, *this* over it), *peer* reached over SSH as root."""
    t = dict(name=who, profile="remote", **CAST[who])
    t.update(this)
    return Settings(this=ThisComponent(**t),
                    peers=[Peer(peer, local_ip=CAST[peer]["local_ip"],
                                public_ip=CAST[peer]["public_ip"], ssh_user="root")],
                    ros=RosSettings(master="turtlebot"))


def laptop_settings(**this) -> Settings:
    """sami, a member behind its home modem; the robot turtlebot runs the master."""
    return _seat("sami", "turtlebot", **this)


def robot_settings(**this) -> Settings:
    """turtlebot, the master behind its telecom router; sami a member."""
    return _seat("turtlebot", "sami", **this)


def res(cid: str, status: str = "pass", summary: str = "", **data) -> CheckResult:
    """A result with a summary and one line of evidence (the advisor tests' results)."""
    return result(cid, status, summary or f"{cid} {status}", data,
                  evidence=[f"evidence of {cid}"])


def healthy_laptop() -> dict[str, CheckResult]:
    """Every check passing, from sami's seat (what the healthy lab should give)."""
    peer = "turtlebot"
    rs = [
        res("isp.internet", dns_ok=True, http_ok=True, failed_part=None,
            url="http://probe.lab.test/"),
        res("isp.public_ip", public_ip="198.51.100.2",
            sources={"http://probe.lab.test/ip": "198.51.100.2"}, agree=True,
            settings_ip="198.51.100.2", matches_settings=True, previous_ip="198.51.100.2",
            changed=False, history=[{"ip": "198.51.100.2", "first_seen": "2024-01-01T00:00:00",
                                     "last_seen": "2024-01-02T00:00:00"}]),
        res("isp.cgnat", wan_ip=None, method="traceroute", cgnat=False, double_nat=False,
            hop=None),
        res("router.local_ip", local_ip="192.168.1.10", interface="eth0",
            gateway="192.168.1.254", expected_ip="192.168.1.10", differs=False),
        res("router.port_free", port=12345, in_use=False, process=None, pid=None),
        res("router.listener", port=12345, listening=True),
        res("router.port_open", ports=[
            {"port": 12345, "reachable": True, "listener": True, "via": "peer:turtlebot"},
            {"port": 23456, "reachable": True, "listener": True, "via": "peer:turtlebot"},
            {"port": 22, "reachable": True, "listener": True, "via": "peer:turtlebot"}],
            test_port=12345, test_port_open=True, public_ip="198.51.100.2"),
        res("linux.hosts", missing=[], wrong=[], duplicates=[], loopback=[]),
        res("linux.resolve", names={"sami": {"resolved": "192.168.1.10",
                                             "expected": "192.168.1.10"},
                                    peer: {"resolved": "203.0.113.2", "expected": "203.0.113.2"}},
            wrong=[], loopback=[]),
        res("linux.ping", peers={peer: {"icmp": True, "tcp22": True}}),
        res("linux.ssh", peers={peer: {"ok": True, "failure": None, "fingerprint": "SHA256:abc"}}),
        res("linux.chat_out", peers={peer: {"ok": True, "failure": None}}),
        res("linux.chat_in", peers={peer: {"ok": True, "failure": None}}),
        res("ros.env", env_uri="http://turtlebot:11311", bashrc_uri="http://turtlebot:11311",
            expected_uri="http://turtlebot:11311", uri_ok=True, ros_ip=None, ros_hostname=None),
        res("ros.master", uri="http://turtlebot:11311", reachable=True,
            topics=[["/rosout", "rosgraph_msgs/Log"]], nodes=["/rosout"]),
        res("ros.node_uris", unreachable=[], checked=2),
        res("ros.pubsub_out", peer=peer, ok=True, failed_hop=None, node=None, uri=None),
        res("ros.pubsub_in", peer=peer, ok=True, failed_hop=None, node=None, uri=None),
    ]
    return {r.id: r for r in rs}


def healthy_robot() -> dict[str, CheckResult]:
    """Every check passing, from turtlebot's seat (the master)."""
    r = healthy_laptop()
    r["isp.public_ip"].data.update(public_ip="203.0.113.2", settings_ip="203.0.113.2",
                                   previous_ip="203.0.113.2",
                                   sources={"http://probe.lab.test/ip": "203.0.113.2"})
    r["router.local_ip"].data.update(local_ip="10.10.10.1", gateway="10.10.10.254",
                                     expected_ip="10.10.10.1")
    r["router.port_open"].data["ports"].append(
        {"port": 11311, "reachable": True, "listener": True, "via": "peer:sami"})
    r["router.port_open"].data["public_ip"] = "203.0.113.2"
    r["linux.resolve"].data["names"] = {
        "turtlebot": {"resolved": "10.10.10.1", "expected": "10.10.10.1"},
        "sami": {"resolved": "198.51.100.2", "expected": "198.51.100.2"}}
    for cid in ("linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"):
        r[cid].data["peers"] = {"sami": r[cid].data["peers"]["turtlebot"]}
    for cid in ("ros.pubsub_out", "ros.pubsub_in"):
        r[cid].data["peer"] = "sami"
    return r


def put(results: dict[str, CheckResult], cid: str, status: str, **data) -> None:
    """Change one result: its status and some data keys."""
    r = results[cid]
    r.status = Status(status)
    r.data.update(data)


def t1(listening: bool, open_: bool, base=None) -> dict[str, CheckResult]:
    r = base or healthy_laptop()
    put(r, "router.listener", "pass" if listening else "fail", listening=listening)
    ports = [{"port": 12345, "reachable": open_, "listener": listening, "via": "echoip"}]
    put(r, "router.port_open", "pass" if open_ else "fail", ports=ports, test_port_open=open_)
    return r


def no_ssh(r: dict[str, CheckResult], failure: str) -> None:
    """The chats, as the checks report them when SSH to the peer failed (or is not set up)."""
    f = "no_user" if failure == "no_user" else f"ssh:{failure}"
    for cid in ("linux.chat_out", "linux.chat_in"):
        put(r, cid, "skip" if failure == "no_user" else "fail",
            peers={"turtlebot": {"ok": False, "failure": f}})


# --------------------------------------------------------------------------- more settings
def complete_settings() -> Settings:
    """A complete set-up as the wizard saves it (turtlebot, the master, and one peer)."""
    s = Settings()
    s.this = ThisComponent(name="turtlebot", role="master", connection="telecom",
                           local_ip="10.10.10.1")
    s.peers = [Peer("sami", "192.168.1.10", "198.51.100.2", "ops")]
    s.ros.master = "turtlebot"
    return s


def ros2_member(**ros) -> Settings:
    return Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10"),
                    peers=[Peer(name="turtlebot", public_ip="203.0.113.2", ssh_user="robot")],
                    ros=RosSettings(master="turtlebot", version=2, **ros))


def ros2_master(*, public_ip: str = "", **ros) -> Settings:
    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1",
                                       public_ip=public_ip),
                    peers=[Peer(name="sami", public_ip="198.51.100.2", ssh_user="me")],
                    ros=RosSettings(master="turtlebot", version=2, **ros))


ROBOT_NET = LocalNet(interface="wlan0", local_ip="10.10.10.1", gateway="10.10.10.254",
                     mac="02:00:0a:0a:0a:01", netmask="255.255.255.0")


def card_robot(connection: str = "telecom", local_ip: str = "10.10.10.1",
               interface: str = "") -> Settings:
    """turtlebot with its public address, for the router card (on ROBOT_NET)."""
    return Settings(this=ThisComponent(name="turtlebot", role="master", connection=connection,
                                       local_ip=local_ip, public_ip="203.0.113.2",
                                       interface=interface),
                    peers=[Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2")],
                    ros=RosSettings(master="turtlebot"))


def named_settings(*peers: str) -> Settings:
    """turtlebot and peers of these names (names are what is tested)."""
    s = Settings()
    s.this = ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1")
    s.peers = [Peer(p, "", "198.51.100.2") for p in peers]
    s.ros.master = "turtlebot"
    return s


SYNC_PEERS = (Peer(name="turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.2"),
              Peer(name="rover", local_ip="10.10.20.1", public_ip="203.0.113.30"))


def folder_sync_settings(folder: Path, interval_s: float = 60, peers: int = 1) -> Settings:
    """sami following its first *peers* peers' public addresses through a shared folder."""
    return Settings(
        this=ThisComponent(name="sami", role="member", profile="remote", local_ip="192.168.1.10",
                           public_ip="198.51.100.2", interface="eth0"),
        peers=[replace(p, sync_key=sync_key_text(p.name)) for p in SYNC_PEERS[:peers]],
        ros=RosSettings(master="turtlebot"),
        probe=ProbeSettings(public_ip_urls=["http://127.0.0.1:9/ip"]),
        sync=SyncSettings(store="folder", folder=str(folder), interval_s=interval_s),
        has_sync=True)


def sync_laptop_settings(**sync) -> Settings:
    """sami, a remote member with one peer; *sync* are its SyncSettings (none: no sync)."""
    return Settings(
        this=ThisComponent(name="sami", role="member", profile="remote", local_ip="192.168.1.10",
                           public_ip="198.51.100.2", interface="eth0"),
        peers=[Peer(name="turtlebot", local_ip="10.10.10.1", public_ip="203.0.113.2",
                    ssh_user="root", sync_key=sync_key_text("turtlebot"))],
        ros=RosSettings(master="turtlebot"),
        probe=ProbeSettings(public_ip_urls=["http://127.0.0.1:9/ip"]),
        sync=SyncSettings(**sync), has_sync=bool(sync))


def settings_with(peer: Peer, **this) -> Settings:
    """This machine (rosnet-test on 127.0.0.1 unless told) and one peer."""
    this.setdefault("name", "rosnet-test")
    this.setdefault("local_ip", "127.0.0.1")
    return Settings(this=ThisComponent(**this), peers=[peer])


def seat_settings(role="master", connection="telecom", profile="remote") -> Settings:
    """turtlebot (the master) or sami (a member), with the other as its one peer."""
    s = Settings()
    name = "turtlebot" if role == "master" else "sami"
    local = "10.10.10.1" if role == "master" else "192.168.1.10"
    s.this = ThisComponent(name=name, role=role, connection=connection, profile=profile,
                           local_ip=local)
    other = Peer("sami", "192.168.1.10", "198.51.100.2", "ops") if role == "master" else \
        Peer("turtlebot", "10.10.10.1", "203.0.113.2", "root", office_ip="172.16.0.5")
    s.peers = [other]
    s.ros.master = "turtlebot"
    return s


def probe_settings(name="turtlebot", local_ip="10.10.10.1", peers=None,
                   profile="remote") -> Settings:
    """This machine with a free test port, and sami as its peer unless *peers* are given."""
    return Settings(this=ThisComponent(name=name, local_ip=local_ip, profile=profile),
                    peers=peers if peers is not None else
                    [Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2")],
                    probe=ProbeSettings(port=free_port()))


def sync_key(name: str):
    """A fixed sync key for the component *name* in tests (the same in every test)."""
    import hashlib

    from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey

    return Ed25519PrivateKey.from_private_bytes(
        hashlib.sha256(b"rosnet-tui test sync key " + name.lower().encode()).digest())


def sync_key_text(name: str) -> str:
    """*name*'s pinned sync_key (what `sync key` prints there)."""
    from rosnet_tui.core.sync.signing import public_text

    return public_text(sync_key(name))


def signed(rec):
    """*rec* signed by its component's test sync key."""
    from rosnet_tui.core.sync.signing import sign_record

    return sign_record(rec, sync_key(rec.name))


def pinned(*names: str) -> dict:
    """What a store's fetch is handed: each name's test sync key (public half)."""
    return {n.lower(): sync_key(n).public_key() for n in names}


def write_sync_key(config_path, name: str) -> None:
    """Give the component whose settings are *config_path* its fixed test sync key."""
    from cryptography.hazmat.primitives import serialization as ser

    from rosnet_tui.core.sync.signing import key_path

    path = key_path(config_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(sync_key(name).private_bytes(ser.Encoding.PEM, ser.PrivateFormat.PKCS8,
                                                  ser.NoEncryption()))
    path.chmod(0o600)


def signed_record(name: str, **kw):
    """A new record of *name*, signed by its test sync key."""
    from rosnet_tui.core.saved.sync_records import new_record

    return signed(new_record(name, **kw))
