"""ROS 2 mutual TLS as the checks see it: this component's fleet certificate (present, from the
fleet CA installed here, naming the right component, not expired, 30 days' warning), and, when a
TLS session to the master fails, a standard-library TLS handshake that names why (the master's
certificate does not name the host dialled, it is from another CA, or the master refused this
component's certificate: expired, or from another CA).
"""

from __future__ import annotations

import socket
import ssl
from typing import Any

from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.ros import fleet_tls
from rosnet_tui.core.ros.fleet_tls import TlsError, TlsPaths

PROBLEM_WORDS = {
    "missing": "this component has no fleet certificate (`rosnet-tui ros apply`; on a member "
               "it pairs with the master: `rosnet-tui ros pair`)",
    "unreadable": "this component's fleet certificate cannot be read",
    "foreign_ca": "this component's certificate is from another CA than the fleet's: pair again "
                  "(`rosnet-tui ros pair --renew`)",
    "wrong_name": "the certificate does not name the component it is on",
    "expired": "this component's fleet certificate has expired: renew it (`rosnet-tui ros pair "
               "--renew`; on the master `rosnet-tui ros apply`)",
    "expiring": "this component's fleet certificate expires within "
                f"{fleet_tls.WARN_DAYS} days: renew it (`rosnet-tui ros pair --renew`)",
}


def local_state(s: Settings, paths: TlsPaths) -> dict[str, Any]:
    """``{"problem": ..., "cn", "sans", "not_after", "days_left"}`` of this component's certificate."""
    out: dict[str, Any] = {"problem": None}
    if not (paths.node_crt.exists() and paths.ca_crt.exists() and paths.node_key.exists()):
        out["problem"] = "missing"
        return out
    try:
        summ = fleet_tls.cert_summary(paths.node_crt)
        ca_id = fleet_tls.ca_key_id(paths.ca_crt)
    except (TlsError, OSError, ValueError):
        out["problem"] = "unreadable"
        return out
    out.update(cn=summ["cn"], sans=summ["sans"], not_after=summ["not_after"],
               days_left=summ["days_left"])
    want = s.master_name if s.is_master else s.this.name
    if summ["issuer_key_id"] != ca_id:
        out["problem"] = "foreign_ca"
    elif want not in summ["sans"]:
        out["problem"] = "wrong_name"
    elif summ["days_left"] <= 0:
        out["problem"] = "expired"
    elif summ["days_left"] <= fleet_tls.WARN_DAYS:
        out["problem"] = "expiring"
    return out


FAR_WORDS = {   # whose router is dialled: (its name in words, what makes its certificate)
    "master": ("the master", "`rosnet-tui ros apply` on the master"),
    "relay": ("the relay", "`rosnet-tui relay apply` on the master"),
}


def handshake(address: str, port: int, server_name: str, paths: TlsPaths,
              timeout: float, far: str = "master") -> tuple[str | None, str]:
    """A TLS handshake with the master's router (*far* "relay": the relay's) as a member's router
    makes it (this component's certificate; the fleet CA; the name dialled checked).
    (problem, words): problem None when the router accepted it; else "wrong_name" (its
    certificate does not name *server_name*), "master_foreign_ca" (its certificate is not from
    this fleet CA), "rejected_expired", "rejected_foreign" (it refused this component's
    certificate), "no_tls", "unreachable"."""
    who, maker = FAR_WORDS[far]
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    try:
        ctx.load_verify_locations(cafile=str(paths.ca_crt))
        ctx.load_cert_chain(str(paths.node_crt), str(paths.node_key))
    except (OSError, ssl.SSLError) as exc:
        return "missing", f"the fleet files cannot be loaded ({exc})"
    try:
        raw = socket.create_connection((address, port), timeout=timeout)
    except OSError as exc:
        return "unreachable", f"TCP {address}:{port}: {exc}"
    try:
        raw.settimeout(timeout)
        with ctx.wrap_socket(raw, server_hostname=server_name) as tls:
            try:   # TLS 1.3: a refused client certificate shows as an alert on the first read
                tls.settimeout(min(timeout, 0.5))
                tls.recv(1)
            except TimeoutError:
                pass
            return None, f"{who}'s router accepted this component's certificate"
    except ssl.SSLCertVerificationError as exc:
        if exc.verify_code == 62:
            return "wrong_name", (f"{who}'s certificate does not name {server_name}, the "
                                  f"name dialled: run {maker}")
        return "master_foreign_ca", (f"{who}'s certificate is not from the fleet CA "
                                     f"installed here ({exc.verify_message}): pair again "
                                     "(`rosnet-tui ros pair --renew`)")
    except ssl.SSLError as exc:
        text = str(exc).upper()
        if "EXPIRED" in text:
            return "rejected_expired", (f"{who}'s router refused this component's "
                                        "certificate: it has expired (`rosnet-tui ros pair "
                                        "--renew`)")
        if any(w in text for w in ("UNKNOWN_CA", "CERTIFICATE_UNKNOWN", "BAD_CERTIFICATE",
                                   "CERTIFICATE_REQUIRED", "DECRYPT_ERROR")):
            return "rejected_foreign", (f"{who}'s router refused this component's "
                                        "certificate: it is not from the master's fleet CA (a "
                                        "member paired with another CA): pair again "
                                        "(`rosnet-tui ros pair --renew`)")
        if "WRONG_VERSION" in text or "RECORD_LAYER" in text or "UNEXPECTED_EOF" in text:
            return "no_tls", f"{who}'s port does not speak TLS (is its security \"none\"?)"
        return "rejected_foreign", f"the TLS handshake failed ({exc.reason or exc})"
    except OSError as exc:
        return "unreachable", f"TLS to {address}:{port}: {exc}"
    finally:
        raw.close()
