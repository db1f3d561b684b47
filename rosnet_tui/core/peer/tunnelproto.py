"""relay.tunnel's peer side: from a peer, reach a component's sshd through the relay as that
peer's own SSH would (core/checks/relay_tunnel.py runs this on every peer it can reach).

The peer logs in to the relay with its own keys (``~/.ssh``, its agent), the relay's host key
checked against its own known_hosts (``~/.ssh/known_hosts``, ``/etc/ssh/ssh_known_hosts``: never
accepted silently), opens a ``direct-tcpip`` channel to the relay's ``127.0.0.1:<port>`` and
reads the host key of the sshd that answers there. No login at the far end: the key is all the
question needs, and the component's side compares it with its own sshd's keys.

Runs on the interpreter of the rosnet-tui installed on the peer (its paramiko), fed as source by
the round's peer agent, whatever that rosnet-tui's version: the standard library only at the
top, paramiko imported when asked; Python 3.8+ syntax, no imports from rosnet_tui. Prints one
line: ``ROSNET_TUNNEL {"key": <base64 or null>, "failure": ..., "detail": ...}``.
"""
# ruff: noqa: UP006, UP035

from __future__ import annotations

import base64
import json
import os
import sys
import time

MARK = "ROSNET_TUNNEL "
FAILURES = ("relay", "down", "not_sshd", "timeout")
CHANNEL_CONNECT_FAILED = 2   # RFC 4254 7.1: nothing accepted the connection at the far end
KNOWN_HOSTS = ("~/.ssh/known_hosts", "/etc/ssh/ssh_known_hosts")


def _report(key=None, failure=None, detail="") -> int:
    print(MARK + json.dumps({"key": key, "failure": failure, "detail": detail[:300]}))
    sys.stdout.flush()
    return 0


def _why(exc) -> str:
    return str(exc) or type(exc).__name__


def probe(host: str, port: int, user: str, tunnel: int, timeout: float) -> int:
    deadline = time.monotonic() + timeout

    def left() -> float:
        return max(deadline - time.monotonic(), 0.05)

    if "invoke" not in sys.modules:
        sys.modules["invoke"] = None   # paramiko's optional ssh_config helper, unused here
    try:
        import paramiko
    except ImportError as exc:
        return _report(failure="relay", detail=f"no paramiko here ({exc})")
    client = paramiko.SSHClient()
    for f in KNOWN_HOSTS:
        path = os.path.expanduser(f)
        if os.path.isfile(path):
            try:
                client.load_system_host_keys(path)
            except (OSError, ValueError, paramiko.SSHException):
                pass
    client.set_missing_host_key_policy(paramiko.RejectPolicy())
    far = None
    try:
        try:
            client.connect(host, port, username=user, timeout=left(), banner_timeout=left(),
                           auth_timeout=left(), allow_agent=True, look_for_keys=True)
        except paramiko.BadHostKeyException:
            return _report(failure="relay", detail=f"the host key of {host} CHANGED: "
                                                   "known_hosts has another")
        except paramiko.AuthenticationException as exc:
            return _report(failure="relay", detail=f"{host} refused this peer's keys for "
                                                   f"{user} ({_why(exc)})")
        except paramiko.SSHException as exc:
            if time.monotonic() >= deadline:
                return _report(failure="timeout", detail=f"no login to {host} in time")
            return _report(failure="relay", detail=f"{host}: {_why(exc)}")
        except OSError as exc:
            return _report(failure="relay", detail=f"no connection to {host}:{port}: "
                                                   f"{_why(exc)}")
        relay = client.get_transport()
        try:
            chan = relay.open_channel("direct-tcpip", ("127.0.0.1", tunnel), ("127.0.0.1", 0),
                                      timeout=left())
        except paramiko.ChannelException as exc:
            if exc.code == CHANNEL_CONNECT_FAILED:
                return _report(failure="down", detail=f"nothing answers at 127.0.0.1:{tunnel} "
                                                      f"on {host}: the tunnel is down")
            return _report(failure="relay", detail=f"{host} does not let {user} open "
                                                   f"127.0.0.1:{tunnel} ({exc.text or exc.code})")
        far = paramiko.Transport(chan)
        far.banner_timeout = far.handshake_timeout = left()
        try:
            far.start_client(timeout=left())
            key = far.get_remote_server_key()
        except Exception as exc:  # noqa: BLE001 - not sshd there, or silent
            if time.monotonic() >= deadline:
                return _report(failure="timeout", detail=f"no SSH handshake at 127.0.0.1:"
                                                         f"{tunnel} on {host} in time")
            return _report(failure="not_sshd", detail=f"127.0.0.1:{tunnel} on {host} does not "
                                                      f"speak SSH: {_why(exc)}")
        return _report(key=base64.b64encode(key.asbytes()).decode("ascii"),
                       detail=f"127.0.0.1:{tunnel} on {host} answers with a "
                              f"{key.get_name()} key")
    except Exception as exc:  # noqa: BLE001 - the relay's connection died under us
        return _report(failure="relay", detail=f"{host}: {_why(exc)}")
    finally:
        for x in (far, client):
            try:
                if x is not None:
                    x.close()
            except Exception:  # noqa: BLE001, S110
                pass


def main(argv) -> int:
    """``HOST PORT USER TUNNEL_PORT TIMEOUT``: the relay's sshd, the login there, the port on
    its loopback, the seconds the probe may take."""
    try:
        host, port, user, tunnel, t = argv[0], int(argv[1]), argv[2], int(argv[3]), float(argv[4])
    except (IndexError, ValueError):
        print("ERROR usage: HOST PORT USER TUNNEL_PORT TIMEOUT")
        return 2
    return probe(host, port, user, tunnel, t)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
