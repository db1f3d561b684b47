"""UPnP IGD (Internet Gateway Device, v1 and v2): the root description and the SOAP actions of its
WANIPConnection (or WANPPPConnection) service that a port forward needs.

Every value the modem returns is checked for its type before use: ports are 1-65535, addresses are
dotted IPv4, leases are whole seconds, texts are short. A modem's UPnP error becomes
:class:`~rosnet_tui.core.upnp.wire.Refused` with its code explained in words.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from xml.sax.saxutils import escape

from rosnet_tui.core.upnp import wire
from rosnet_tui.core.upnp.wire import HostileAnswer, ModemError, Refused

WAN_SERVICES = ("urn:schemas-upnp-org:service:WANIPConnection:2",
                "urn:schemas-upnp-org:service:WANIPConnection:1",
                "urn:schemas-upnp-org:service:WANPPPConnection:1")
MAX_LISTED = 256   # GetGenericPortMappingEntry calls at most (a modem could count forever)

# The UPnP errors a port-forward request meets, in words.
UPNP_ERRORS: dict[int, tuple[str, str]] = {
    401: ("InvalidAction", "the modem does not offer this action"),
    402: ("InvalidArgs", "the modem rejected the request's values"),
    501: ("ActionFailed", "the modem could not do it (often: it has no public address of its own, "
                          "or its forwarding is switched off)"),
    606: ("ActionNotAuthorized", "the modem's UPnP rules do not allow this forward (this port or "
                                 "this machine is not permitted)"),
    713: ("SpecifiedArrayIndexInvalid", "no more entries"),
    714: ("NoSuchEntryInArray", "the modem holds no such forward"),
    715: ("WildCardNotPermittedInSrcIP", "the modem needs a specific remote host"),
    716: ("WildCardNotPermittedInExtPort", "the modem needs a specific external port"),
    718: ("ConflictInMappingEntry", "the external port is already forwarded to another machine, "
                                    "or the modem's secure mode lets a machine forward ports only "
                                    "to itself"),
    724: ("SamePortValuesRequired", "the modem only forwards a port to the same port number"),
    725: ("OnlyPermanentLeasesSupported", "the modem only accepts forwards that never expire; "
                                          "rosnet-tui only makes forwards with a lease"),
    726: ("RemoteHostOnlySupportsWildcard", "the modem cannot restrict a forward to one remote "
                                            "host"),
    727: ("ExternalPortOnlySupportsWildcard", "the modem cannot forward a specific external port"),
    728: ("NoPortMapsAvailable", "the modem's table of forwards is full"),
    729: ("ConflictWithOtherMechanisms", "the port is taken by another mechanism on the modem (its "
                                         "own service or a forward set in its web page)"),
    732: ("WildCardNotPermittedInIntPort", "the modem needs a specific internal port"),
}


@dataclass
class Igd:
    """An IGD's WAN connection service: where to send SOAP, and who the device is."""

    host: str                 # the modem's LAN address (the SSDP answer came from it)
    location: str             # its root description's URL
    control_url: str          # the WAN*Connection service's control URL (on the same host)
    service: str              # the service type
    udn: str                  # the root device's unique device name (uuid:...)
    friendly_name: str = ""
    model: str = ""
    source_ip: str | None = None

    @property
    def version(self) -> int:
        return 2 if self.service.endswith(":2") else 1


@dataclass
class IgdMapping:
    protocol: str           # "TCP" | "UDP"
    external_port: int
    internal_client: str    # dotted IPv4
    internal_port: int
    description: str
    lease_s: int            # 0: no expiry
    enabled: bool
    remote_host: str = ""   # "" : any remote host


# --------------------------------------------------------------------------- typed values
def as_port(value: str | None, what: str, *, zero: bool = False) -> int:
    v = (value or "").strip()
    if not v.isascii() or not v.isdigit() or len(v) > 5 or \
            not (0 if zero else 1) <= int(v) <= 65535:
        raise HostileAnswer(f"the modem's {what} is not a port number ({wire.shown(v, 20)!r})")
    return int(v)


def as_seconds(value: str | None, what: str) -> int:
    """A lease in whole seconds, ASCII digits only ("" is 0: no expiry)."""
    return wire.ascii_number((value or "0").strip() or "0", f"{what} (in seconds)")


def as_ipv4(value: str | None, what: str, *, empty: bool = False) -> str:
    v = (value or "").strip()
    if not v and empty:
        return ""
    ip = wire.lan_ipv4(v)
    if ip is None:
        raise HostileAnswer(f"the modem's {what} is not an IPv4 address "
                            f"({wire.shown(v, 40)!r})")
    return ip


def as_bool(value: str | None, what: str) -> bool:
    v = (value or "").strip().lower()
    if v not in ("0", "1", "true", "false", "yes", "no"):
        raise HostileAnswer(f"the modem's {what} is not a yes/no value "
                            f"({wire.shown(v, 20)!r})")
    return v in ("1", "true", "yes")


# --------------------------------------------------------------------------- description
def describe(location: str, host: str, deadline: float, source_ip: str | None = None) -> Igd:
    """Fetch and read the root description at *location* (which must be on *host*)."""
    ans = wire.http_request("GET", location, host, deadline, source_ip=source_ip)
    if ans.status != 200:
        raise HostileAnswer(f"GET {location} answered HTTP {ans.status}, not the description")
    root = wire.parse_xml(ans.body, "device description")
    if wire.local_name(root.tag) != "root":
        raise HostileAnswer("the modem's device description has no <root>")
    base = location
    for el in root:
        if wire.local_name(el.tag) == "URLBase" and (el.text or "").strip():
            base = wire.resolve(location, el.text or "", host)
    device = next((el for el in root if wire.local_name(el.tag) == "device"), None)
    if device is None:
        raise HostileAnswer("the modem's device description has no <device>")
    udn = wire.clean_text(wire.child_text(device, "UDN"), "UDN")
    name = wire.clean_text(wire.child_text(device, "friendlyName"), "friendlyName")
    model = wire.clean_text(wire.child_text(device, "modelName"), "modelName")
    found: dict[str, str] = {}
    for el in device.iter():
        if wire.local_name(el.tag) != "service":
            continue
        stype = (wire.child_text(el, "serviceType") or "").strip()
        if stype in WAN_SERVICES and stype not in found:
            found[stype] = wire.resolve(base, wire.child_text(el, "controlURL") or "", host)
    for stype in WAN_SERVICES:
        if stype in found:
            return Igd(host, location, found[stype], stype, udn, name, model, source_ip)
    raise ModemError("the modem speaks UPnP, but offers no WAN connection service (it cannot "
                     "forward ports over UPnP)")


# --------------------------------------------------------------------------- SOAP
def soap(igd: Igd, action: str, args: list[tuple[str, str | int]], deadline: float
         ) -> dict[str, str]:
    """Call *action*; its output arguments as texts. A UPnP error raises Refused."""
    inner = "".join(f"<{k}>{escape(str(v))}</{k}>" for k, v in args)
    body = ('<?xml version="1.0"?>\r\n<s:Envelope xmlns:s="http://schemas.xmlsoap.org/soap/'
            'envelope/" s:encodingStyle="http://schemas.xmlsoap.org/soap/encoding/"><s:Body>'
            f'<u:{action} xmlns:u="{igd.service}">{inner}</u:{action}></s:Body></s:Envelope>'
            ).encode()
    ans = wire.http_request("POST", igd.control_url, igd.host, deadline, body=body,
                            headers={"Content-Type": 'text/xml; charset="utf-8"',
                                     "SOAPAction": f'"{igd.service}#{action}"'},
                            source_ip=igd.source_ip)
    if ans.status == 500 and ans.body:
        raise _fault(ans.body, action)
    if ans.status != 200:
        raise HostileAnswer(f"{action} answered HTTP {ans.status}")
    root = wire.parse_xml(ans.body, f"{action} answer")
    resp = next((el for el in root.iter() if wire.local_name(el.tag) == f"{action}Response"),
                None)
    if resp is None:
        raise HostileAnswer(f"the modem's answer to {action} has no {action}Response")
    out: dict[str, str] = {}
    for el in resp:
        if len(el):
            raise HostileAnswer(f"the modem's {wire.local_name(el.tag)} holds elements, not text")
        out[wire.local_name(el.tag)] = wire.clean_text(el.text, wire.local_name(el.tag))
    return out


def _fault(body: bytes, action: str) -> ModemError:
    root = wire.parse_xml(body, f"{action} error")
    err = next((el for el in root.iter() if wire.local_name(el.tag) == "UPnPError"), None)
    if err is None:
        return HostileAnswer(f"{action} failed with a SOAP fault that is not a UPnP error")
    code_text = (wire.child_text(err, "errorCode") or "").strip()
    try:
        code = wire.ascii_number(code_text, "UPnP error code", digits=4)
    except HostileAnswer:
        return HostileAnswer(f"{action} failed with a malformed UPnP error code "
                             f"({wire.shown(code_text, 20)!r})")
    desc = wire.clean_text(wire.child_text(err, "errorDescription"), "errorDescription")
    name, words = UPNP_ERRORS.get(code, (desc or "unknown", f"the modem said {desc or 'no more'}"))
    return Refused("upnp", code, desc or name, words)


# --------------------------------------------------------------------------- actions
def external_ip(igd: Igd, deadline: float) -> str:
    """The modem's external address as it reports it ("" when it reports none)."""
    out = soap(igd, "GetExternalIPAddress", [], deadline)
    return as_ipv4(out.get("NewExternalIPAddress"), "external address", empty=True)


def _mapping(out: dict[str, str], protocol: str, external_port: int) -> IgdMapping:
    return IgdMapping(protocol, external_port,
                      as_ipv4(out.get("NewInternalClient"), "internal client"),
                      as_port(out.get("NewInternalPort"), "internal port"),
                      out.get("NewPortMappingDescription", ""),
                      as_seconds(out.get("NewLeaseDuration"), "lease"),
                      as_bool(out.get("NewEnabled", "1"), "enabled flag"),
                      out.get("NewRemoteHost", ""))


def get_mapping(igd: Igd, protocol: str, external_port: int, deadline: float
                ) -> IgdMapping | None:
    """The modem's forward of *protocol* *external_port*, or None when it holds none."""
    try:
        out = soap(igd, "GetSpecificPortMappingEntry",
                   [("NewRemoteHost", ""), ("NewExternalPort", external_port),
                    ("NewProtocol", protocol)], deadline)
    except Refused as exc:
        if exc.code in (714, 402):
            return None
        raise
    return _mapping(out, protocol, external_port)


def list_mappings(igd: Igd, deadline: float) -> list[IgdMapping]:
    """Every forward the modem holds (at most MAX_LISTED)."""
    out: list[IgdMapping] = []
    for i in range(MAX_LISTED):
        if time.monotonic() > deadline:
            raise wire.NoAnswer("the modem did not finish listing its forwards in time")
        try:
            got = soap(igd, "GetGenericPortMappingEntry", [("NewPortMappingIndex", i)], deadline)
        except Refused as exc:
            if exc.code in (713, 714, 402):
                return out
            raise
        proto = got.get("NewProtocol", "").upper()
        if proto not in ("TCP", "UDP"):
            raise HostileAnswer(f"the modem lists a forward with protocol "
                            f"{wire.shown(proto, 10)!r}")
        out.append(_mapping(got, proto, as_port(got.get("NewExternalPort"), "external port")))
    return out


def add_mapping(igd: Igd, protocol: str, external_port: int, internal_client: str,
                internal_port: int, description: str, lease_s: int, deadline: float) -> None:
    soap(igd, "AddPortMapping",
         [("NewRemoteHost", ""), ("NewExternalPort", external_port), ("NewProtocol", protocol),
          ("NewInternalPort", internal_port), ("NewInternalClient", internal_client),
          ("NewEnabled", 1), ("NewPortMappingDescription", description),
          ("NewLeaseDuration", lease_s)], deadline)


def delete_mapping(igd: Igd, protocol: str, external_port: int, deadline: float) -> None:
    try:
        soap(igd, "DeletePortMapping", [("NewRemoteHost", ""), ("NewExternalPort", external_port),
                                        ("NewProtocol", protocol)], deadline)
    except Refused as exc:
        if exc.code != 714:  # already gone
            raise
