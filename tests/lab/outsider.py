"""What a stranger tries from the lab's outsider host (192.0.2.66: on the internet, no peer).

Every helper runs a short program inside the outsider's namespace (the development interpreter,
which has eclipse-zenoh and paramiko) and returns what it got; each is bounded by *timeout*.
The outsider knows no names of the fleet: it dials public addresses.

- :func:`zenoh_session`: a Zenoh client session to ``tcp/`` or ``tls/<ip>:<port>`` (TLS: with a
  certificate of its own CA, not the fleet's, or with none), then the ROS 2 graph (liveliness tokens under
  ``@ros2_lv``) and three puts on ``/chatter``'s key;
- :func:`get_system_state`: XML-RPC ``getSystemState`` on a ROS 1 master;
- :func:`ssh_auth_none`: the SSH methods offered to *user* (paramiko ``auth_none``, no login).
"""

from __future__ import annotations

import json
import subprocess
import sys
from typing import Any

from .lab import Lab

HOST = "outsider"

_ZENOH = r"""
import json, os, sys, tempfile, time
import zenoh
from rosnet_tui.core.exposure import outsider
ep, t, ca = sys.argv[1], float(sys.argv[2]), sys.argv[3]
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([ep]))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/timeout_ms", str(int(t * 1000)))
conf.insert_json5("connect/exit_on_failure", "true")
if ep.startswith("tls/") and ca:      # no certificate of its own; the server checked with *ca*
    conf.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": ca, "verify_name_on_connect": False}))
elif ep.startswith("tls/"):
    d = tempfile.mkdtemp()
    pems = outsider.foreign_pems()
    for k, v in pems.items():
        open(os.path.join(d, k), "w").write(v)
    conf.insert_json5("transport/link/tls", json.dumps({
        "root_ca_certificate": os.path.join(d, "crt"),
        "connect_certificate": os.path.join(d, "crt"), "connect_private_key": os.path.join(d, "key"),
        "verify_name_on_connect": False}))
out = {"session": False}
try:
    s = zenoh.open(conf)
except Exception as e:
    out["error"] = "%s: %s" % (type(e).__name__, e)
    print("OUTSIDER " + json.dumps(out)); sys.exit(0)
out["session"] = True
tokens = [str(r.ok.key_expr) for r in s.liveliness().get("@ros2_lv/**", timeout=t) if r.ok]
out["tokens"] = tokens
pub = 0
for i in range(3):
    s.put("0/chatter/std_msgs::msg::dds_::String_/RIHS01_x", b"outsider %d" % i); pub += 1
out["published"] = pub
s.close()
print("OUTSIDER " + json.dumps(out))
"""

_XMLRPC = r"""
import json, sys, xmlrpc.client, socket
ip, port, t = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
socket.setdefaulttimeout(t)
try:
    code, msg, state = xmlrpc.client.ServerProxy("http://%s:%d/" % (ip, port)).getSystemState("/outsider")
    print("OUTSIDER " + json.dumps({"ok": code == 1, "state": state}))
except Exception as e:
    print("OUTSIDER " + json.dumps({"ok": False, "error": "%s: %s" % (type(e).__name__, e)}))
"""

_SSH = r"""
import json, socket, sys
import paramiko
ip, port, user, t = sys.argv[1], int(sys.argv[2]), sys.argv[3], float(sys.argv[4])
try:
    sock = socket.create_connection((ip, port), timeout=t)
    tr = paramiko.Transport(sock)
    tr.start_client(timeout=t)
    try:
        tr.auth_none(user); methods = ["none"]
    except paramiko.BadAuthenticationType as e:
        methods = list(e.allowed_types)
    tr.close()
    print("OUTSIDER " + json.dumps({"methods": methods}))
except Exception as e:
    print("OUTSIDER " + json.dumps({"error": "%s: %s" % (type(e).__name__, e)}))
"""


def _run(lab: Lab, script: str, *args: str, timeout: float) -> dict[str, Any]:
    try:
        r = lab.run(HOST, [sys.executable, "-c", script, *args], timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"no answer within {timeout:.1f} s", "session": False, "ok": False}
    for line in r.stdout.splitlines():
        if line.startswith("OUTSIDER "):
            return json.loads(line[len("OUTSIDER "):])
    return {"error": f"no report: {r.stderr.strip()[-400:]}", "session": False, "ok": False}


def zenoh_session(lab: Lab, ip: str, port: int, *, tls: bool = False,
                  timeout: float = 3.0, no_cert_ca: str = "") -> dict[str, Any]:
    """{"session": bool, "tokens": [...], "published": n, "error": str}. With *no_cert_ca* (a
    CA certificate's path, e.g. the fleet's, which is no secret): TLS with no certificate of
    the outsider's own, the server checked against that CA."""
    ep = f"{'tls' if tls or no_cert_ca else 'tcp'}/{ip}:{port}"
    return _run(lab, _ZENOH, ep, str(timeout), no_cert_ca, timeout=timeout + 8)


def get_system_state(lab: Lab, ip: str, port: int = 11311,
                     timeout: float = 3.0) -> dict[str, Any]:
    """{"ok": bool, "state": [...], "error": str}."""
    return _run(lab, _XMLRPC, ip, str(port), str(timeout), timeout=timeout + 5)


def ssh_auth_none(lab: Lab, ip: str, port: int = 22, user: str = "root",
                  timeout: float = 3.0) -> dict[str, Any]:
    """{"methods": [...]} or {"error": str}."""
    return _run(lab, _SSH, ip, str(port), user, str(timeout), timeout=timeout + 5)
