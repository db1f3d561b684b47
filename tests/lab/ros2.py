"""The lab as a ROS 2 network over rmw_zenoh (no ROS 2 distribution installs here).

``with Ros2World(lab) as w:`` turns the built lab into the ROS 2 path of the product and back:

- a real Zenoh router (eclipse-zenoh in router mode, what ``rmw_zenohd`` is) on each computer,
  started from the JSON5 config file ``rosnet-tui ros apply`` writes: on the robot (the master,
  turtlebot) listening on ``tcp/0.0.0.0:7447``; on the laptop (sami, a member) connecting out to
  ``tcp/turtlebot:7447``, which the laptop's hosts file maps to the robot's public IP;
- the robot's modem forwards TCP 7447 (the router) and TCP 22; the laptop's modem forwards TCP 22
  only. SSH is the path the checks use to run the peer's side of an exchange; no ROS traffic
  needs it, and the ``member_unforwarded`` variant takes it away;
- ~/.bashrc on both: RMW_IMPLEMENTATION, ROS_DOMAIN_ID, ROS_DISTRO, ZENOH_ROUTER_CONFIG_URI;
- rosnet-tui installed in each computer's home as the README's pipx line leaves it
  (tests/lab/readme_install.py); an SSH session's python3 there has no eclipse-zenoh, so the
  checks' peer side runs with that installation, as on a robot (``uninstall(host)`` takes it away);
- stand-in nodes (tests/lab/ros2_scripts/node.py) behave on the wire as rmw_zenoh nodes do.

Leaving the block stops the routers and nodes and puts the ROS 1 lab back (lab.reset()).
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

from . import readme_install, topology
from .lab import Lab, _write_in_place
from .topology import ADDR, COMPUTERS

SCRIPTS = Path(__file__).resolve().parent / "ros2_scripts"
ZROUTER = SCRIPTS / "zrouter.py"
ZLINKS = SCRIPTS / "zlinks.py"
NODE = SCRIPTS / "node.py"
DELAY_RELAY = Path(__file__).resolve().parent / "delay_relay.py"
# The ROS step's checks under ROS 2 (security.outsider: the outsider is refused, issue 22)
ROS2_IDS = ["ros2.env", "ros2.router", "ros2.graph", "ros2.pubsub_out", "ros2.pubsub_in",
            "ros2.link", "security.outsider"]


class Ros2World:
    def __init__(self, lab: Lab, distro: str = "jazzy") -> None:
        self.lab = lab
        self.distro = distro
        self.routers: dict[str, subprocess.Popen] = {}
        self.nodes: list[subprocess.Popen] = []
        self.bash_extra: dict[str, dict[str, str]] = {h: {} for h in COMPUTERS}
        self.ros_extra: dict[str, Any] = {}     # [ros] values of every computer's settings
        self.shaped: str | None = None          # the robot's modem's rate both ways (tc tbf)
        self.relinking = False                  # a router (re)started: see wait_linked


    # ------------------------------------------------------------------ settings and files
    def settings(self, host: str, **ros: Any):
        s = self.lab.settings(host)
        return replace(s, ros=replace(s.ros, version=2, zenoh_port=topology.ZENOH_PORT,
                                      domain_id=0, **{**self.ros_extra, **ros}))

    def set_security(self, value: str) -> None:
        """[ros] security of every computer; configs rewritten and routers restarted
        (healthy() puts the default back)."""
        self.ros_extra["security"] = value
        for h in self.lab.COMPUTERS:
            self.config_path(h)
            self.write_router_config(h)
        for h in list(self.routers):
            self.start_router(h)

    def config_path(self, host: str, **ros: Any) -> Path:
        from rosnet_tui.core.saved.settings import atomic_write_text, render_settings

        path = self.lab.home(host) / ".config" / "rosnet-tui" / "config.toml"
        atomic_write_text(path, render_settings(self.settings(host, **ros)), mode=0o644)
        return path

    def router_config_path(self, host: str) -> Path:
        return self.lab.home(host) / ".config" / "rosnet-tui" / "zenoh-router.json5"

    def tls_paths(self, host: str):
        """*host*'s fleet TLS files (~/.config/rosnet-tui/tls in its home)."""
        from rosnet_tui.core.ros import fleet_tls

        return fleet_tls.tls_paths(self.lab.home(host) / ".config" / "rosnet-tui")

    def master_host(self) -> str:
        return next(h for h in self.lab.COMPUTERS if self.settings(h).is_master)

    def ensure_tls(self, host: str) -> None:
        """Mutual TLS (the default): the fleet CA and certificate on the master as `ros apply`
        makes them there; a member's key made in its home and signed by that CA, as pairing
        leaves them (tests/test_pairing_lab.py pairs over SSH for real)."""
        from rosnet_tui.core.ros import fleet_tls, pairing, ros2

        s = self.settings(host)
        if not ros2.mtls(s):
            return
        m = self.master_host()
        mp = self.tls_paths(m)
        pairing.prepare_master(self.settings(m), mp)
        if host != m and pairing.needs_pairing(s, self.tls_paths(host)) is not None:
            paths = self.tls_paths(host)
            fleet_tls.set_removed(mp, s.this.name, removed=False)   # a test took it out
            ca, cert = fleet_tls.sign_request(mp, fleet_tls.make_request(paths, s.this.name),
                                              master=s.master_name,
                                              members=pairing.member_names(self.settings(m)))
            fleet_tls.install(paths, ca, cert)

    def remove_tls(self, host: str) -> None:
        import shutil

        shutil.rmtree(self.tls_paths(host).dir, ignore_errors=True)

    def write_router_config(self, host: str, text: str | None = None) -> Path:
        from rosnet_tui.core.ros import ros2

        path = self.router_config_path(host)
        path.parent.mkdir(parents=True, exist_ok=True)
        if text is None:
            self.ensure_tls(host)
            text = ros2.render_router_config(self.settings(host), self.tls_paths(host))
        path.write_text(text)
        return path

    def exports(self, host: str) -> dict[str, str]:
        out = {"RMW_IMPLEMENTATION": "rmw_zenoh_cpp", "ROS_DOMAIN_ID": "0",
               "ROS_DISTRO": self.distro,
               "ZENOH_ROUTER_CONFIG_URI": str(self.router_config_path(host))}
        out.update(self.bash_extra[host])
        return {k: v for k, v in out.items() if v != ""}

    def write_bashrc(self, host: str, **extra: str) -> None:
        """~/.bashrc of *host* with the ROS 2 exports (*extra* adds or, with "", removes)."""
        self.bash_extra[host].update(extra)
        lines = [f"# ~/.bashrc of {self.lab.hostname(host)} (rosnet-tui network lab, ROS 2)"]
        lines += [f"export {k}='{v}'" if " " in v or '"' in v else f"export {k}={v}"
                  for k, v in self.exports(host).items()]
        _write_in_place(self.lab.bashrc_path(host), "\n".join(lines) + "\n")

    def env(self, host: str) -> dict[str, str]:
        """*host*'s environment as a shell that sourced its ~/.bashrc has it."""
        env = self.lab.env(host)
        env.update(self.exports(host))
        return env

    def forward(self, robot: str = "ros2", laptop: str = "ssh") -> None:
        self.lab._set_forwarding("robot", robot)
        self.lab._set_forwarding("laptop", laptop)

    def shape_robot(self, rate: str | None, latency: str = "400ms") -> None:
        """The robot's modem shaped to *rate* ("2mbit") both ways: tc tbf on what leaves its WAN
        (the robot's upload) and its LAN (its download), queueing up to *latency* of it; None
        takes it off (healthy() does)."""
        self.lab.shape_robot(rate, latency)
        self.shaped = rate

    @contextlib.contextmanager
    def delay_to_master(self, delay_ms: float, port: int = 17447) -> Iterator[None]:
        """The laptop's router reaches the master's through a userspace hop on the robot's modem
        (tests/lab/delay_relay.py on its public address, *port*, to the robot's 7447) that holds
        every chunk *delay_ms* ms each way: the lab's delay, this kernel having no netem. The
        laptop's router is restarted on that path, and on its own after the block."""
        from rosnet_tui.core.ros import ros2 as ros2_cfg

        rule = f"INPUT -p tcp -d {ADDR.ROBOT_PUBLIC} --dport {port} -j ACCEPT"
        self.lab._in_ns("robot_modem", f"iptables -I {rule}")
        relay = self.lab.spawn("robot_modem", [
            sys.executable, str(DELAY_RELAY), ADDR.ROBOT_PUBLIC, str(port),
            ADDR.ROBOT_LOCAL, str(topology.ZENOH_PORT), f"{delay_ms:g}", "300"])
        try:
            if not self.lab.wait_output(relay, r"RELAY READY", timeout=10):
                raise RuntimeError(f"the delay relay did not start: {self.lab.output(relay)}")
            cfg = ros2_cfg.loads_json5(self.router_config_path("laptop").read_text())
            eps = cfg["connect"]["endpoints"]
            cfg["connect"]["endpoints"] = [e.replace(f":{topology.ZENOH_PORT}", f":{port}")
                                           for e in eps]
            self.write_router_config("laptop", json.dumps(cfg, indent=2))
            self.start_router("laptop")
            yield
        finally:
            self.lab.kill(relay, grace=0.5)
            self.lab._in_ns("robot_modem", f"iptables -D {rule}", check=False)
            self.write_router_config("laptop")
            self.start_router("laptop")

    def uninstall(self, host: str) -> None:
        """Take rosnet-tui off *host* as ``pipx uninstall rosnet-tui`` would (healthy() puts it
        back)."""
        readme_install.uninstall(self.lab.home(host))

    # ------------------------------------------------------------------ processes
    def start_router(self, host: str, port: int = 7447, timeout: float = 15.0) -> subprocess.Popen:
        self.stop_router(host)
        log = open(self.lab.log_path(f"zrouter-{host}"), "w")  # noqa: SIM115
        proc = self.lab.spawn(host, [sys.executable, str(ZROUTER),
                                     str(self.router_config_path(host))],
                              stdout=log, stderr=subprocess.STDOUT)
        log.close()
        self.routers[host] = proc
        if not self.lab.wait_listening(host, port, timeout=timeout, proc=proc):
            raise RuntimeError(f"the Zenoh router on {host} did not start: "
                               + self.lab.log_path(f"zrouter-{host}").read_text()[-2000:])
        self.relinking = True
        return proc

    def member_hosts(self) -> list[str]:
        master = self.master_host()
        return [h for h in self.lab.COMPUTERS if h != master]

    def router_zid(self, host: str) -> str | None:
        """The id *host*'s router printed at start (None before it did)."""
        text = self.lab.log_path(f"zrouter-{host}").read_text(errors="replace")
        for line in text.splitlines():
            if line.startswith("ZROUTER "):
                return line.split()[1]
        return None

    def linked(self, timeout: float = 20.0) -> dict[str, bool]:
        """{member: its router has a session with the master's}, waiting (bounded) for all."""
        master, members = self.master_host(), self.member_hosts()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not all(
                self.router_zid(m) for m in members):   # printed once the session is up
            time.sleep(0.02)
        r = self.lab.run(master, [sys.executable, str(ZLINKS), "tcp/127.0.0.1:7447",
                                  str(len(members)), str(timeout)], timeout=timeout + 15)
        line = next((x for x in r.stdout.splitlines() if x.startswith("ZLINKS ")), None)
        if line is None:
            raise RuntimeError(f"no link report from the master's router: {r.stdout}{r.stderr}")
        routers = {z.lstrip("0") for z in json.loads(line[len("ZLINKS "):])["routers"]}
        return {m: (self.router_zid(m) or "-").lstrip("0") in routers for m in members}

    def wait_linked(self, timeout: float = 20.0) -> None:
        """Until every member's router has a session with the master's (bounded): after a router
        (re)starts the others re-dial every 4 s at most, and a test begun before found no link
        and no message (ROS 2 lab tests after one that restarted a router failed in whole-file
        runs and passed alone)."""
        links = self.linked(timeout)
        if not all(links.values()):
            raise RuntimeError(f"members' routers not linked to the master's: {links}")
        self.relinking = False

    def stop_router(self, host: str) -> None:
        proc = self.routers.pop(host, None)
        if proc is not None:
            self.lab.kill(proc, grace=1.0)

    def node(self, host: str, role: str, *, connect: str = "tcp/127.0.0.1:7447",
             mode: str = "peer", topic: str = "/chatter", name: str | None = None,
             domain: int = 0, distro: str | None = None) -> subprocess.Popen:
        """A stand-in rmw_zenoh node on *host*; waits (bounded) until its session is open."""
        argv = [sys.executable, str(NODE), role, "--connect", connect, "--mode", mode,
                "--topic", topic, "--domain", str(domain), "--distro", distro or self.distro]
        if name:
            argv += ["--name", name]
        proc = self.lab.spawn(host, argv)
        self.nodes.append(proc)
        if not self.lab.wait_output(proc, r"NODE \S+", timeout=10):
            raise RuntimeError(f"stand-in node on {host} did not start: {self.lab.output(proc)}")
        return proc

    def check(self, host: str, *, step: str = "ros", config: Path | None = None,
              env: dict[str, str] | None = None, timeout: float = 90) -> dict[str, dict]:
        """`rosnet-tui check --json --step STEP` on *host*: {check id: entry}."""
        r = self.lab.rosnet(host, "check", "--json", "--step", step, "--config",
                            str(config or self.config_path(host)),
                            env=env or self.env(host), timeout=timeout)
        assert r.stdout.strip(), r.stderr
        return {c["id"]: c for c in json.loads(r.stdout)["checks"]}

    # ------------------------------------------------------------------ the world
    def __enter__(self) -> Ros2World:
        self.lab.reset()
        try:
            self.forward()
            for h in COMPUTERS:
                readme_install.install(self.lab.home(h))
                self.config_path(h)
                self.write_router_config(h)
                self.write_bashrc(h)
            self.start_router("robot")
            self.start_router("laptop")
        except BaseException:
            self.__exit__()
            raise
        return self

    def healthy(self) -> None:
        """Back to the healthy ROS 2 network (after a variant inside the block)."""
        for p in self.nodes:
            self.lab.kill(p, grace=0.5)
        self.nodes.clear()
        self.bash_extra = {h: {} for h in COMPUTERS}
        restart = bool(self.ros_extra)
        self.ros_extra = {}
        if self.shaped:
            self.shape_robot(None)
        self.forward()
        for h in COMPUTERS:
            self.lab.write_hosts(h, topology.hosts_text(h))
            self.config_path(h)
            self.write_router_config(h)
            self.write_bashrc(h)
            readme_install.install(self.lab.home(h))    # quick when it is there already
            if restart or h not in self.routers or self.routers[h].poll() is not None:
                self.start_router(h)
        if self.relinking:      # a router (re)started here or in the test before
            # a member's router started against a broken path (a test's wrong hosts entry) may
            # never link (it keeps what it resolved): started anew, once
            stale = [m for m, ok in self.linked(timeout=6.0).items() if not ok]
            for m in stale:
                self.start_router(m)
            self.wait_linked()

    def __exit__(self, *exc: Any) -> None:
        if self.shaped:
            self.shape_robot(None)
        for p in self.nodes:
            self.lab.kill(p, grace=0.5)
        self.nodes.clear()
        for h in list(self.routers):
            self.stop_router(h)
        self.lab.reset()
        for h in self.lab.COMPUTERS:
            self.lab.config_path(h)
            self.router_config_path(h).unlink(missing_ok=True)
            self.remove_tls(h)


__all__ = ["ADDR", "ROS2_IDS", "Ros2World"]
