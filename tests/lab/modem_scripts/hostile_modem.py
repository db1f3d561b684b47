"""A hostile modem for the lab (issue 34): run in the robot modem's namespace as
``python3 hostile_modem.py MODE GATEWAY``. It answers SSDP (UDP 1900) with a LOCATION on itself and
serves a device description and SOAP answers (TCP 5000), broken the way MODE says:

- chunk:   GetExternalIPAddress answered chunked, with a chunk size of -6;
- digits:  the mapping list carries a port written with a superscript digit;
- snowman: the control URL is /ctl/<U+2603>;
- c1:      C1 control characters in the friendly name and a forward's description;
- flood:   2000 junk datagrams answer each SSDP search, before the real answer;
- wan:IP:  GetExternalIPAddress answers IP (0.0.0.0, 224.0.0.1, ...), otherwise a good modem.

Standard library only. Stops on SIGTERM."""

from __future__ import annotations

import socket
import sys
import threading

MODE, GW = sys.argv[1], sys.argv[2]
C1 = "\u009b31m\u009d0;pwned\u009c"
CONTROL = "/ctl/\u2603" if MODE == "snowman" else "/ctl/IPConn"
NAME = f"hostile{C1}modem" if MODE == "c1" else "hostile modem"


def description() -> bytes:
    return ('<?xml version="1.0"?><root xmlns="urn:schemas-upnp-org:device-1-0"><device>'
            "<deviceType>urn:schemas-upnp-org:device:InternetGatewayDevice:1</deviceType>"
            f"<friendlyName>{NAME}</friendlyName><UDN>uuid:hostile-1</UDN><deviceList><device>"
            "<serviceList><service><serviceType>urn:schemas-upnp-org:service:WANIPConnection:1"
            f"</serviceType><controlURL>{CONTROL}</controlURL></service></serviceList></device>"
            "</deviceList></device></root>").encode()


def soap(action: str, **out: str) -> bytes:
    args = "".join(f"<{k}>{v}</{k}>" for k, v in out.items())
    return ('<?xml version="1.0"?><s:Envelope xmlns:s="http://schemas.xmlsoap.org/soap/envelope/">'
            f'<s:Body><u:{action}Response xmlns:u="urn:x">{args}</u:{action}Response></s:Body>'
            "</s:Envelope>").encode()


def fault(code: int) -> bytes:
    return ('<?xml version="1.0"?><s:Envelope xmlns:s="http://schemas.xmlsoap.org/soap/envelope/">'
            "<s:Body><s:Fault><faultcode>s:Client</faultcode><faultstring>UPnPError</faultstring>"
            '<detail><UPnPError xmlns="urn:schemas-upnp-org:control-1-0">'
            f"<errorCode>{code}</errorCode><errorDescription>x</errorDescription>"
            "</UPnPError></detail></s:Fault></s:Body></s:Envelope>").encode()


def http(body: bytes, status: str = "200 OK") -> bytes:
    return (f"HTTP/1.1 {status}\r\nContent-Type: text/xml\r\nContent-Length: {len(body)}\r\n"
            "Connection: close\r\n\r\n").encode() + body


def answer(req: bytes) -> bytes:
    if req.startswith(b"GET"):
        return http(description())
    if b"#GetExternalIPAddress" in req:
        if MODE == "chunk":
            return (b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n"
                    b"5\r\n<root\r\n-6\r\nxxxxxx\r\n0\r\n\r\n")
        wan = MODE[4:] if MODE.startswith("wan:") else "192.0.2.1"
        return http(soap("GetExternalIPAddress", NewExternalIPAddress=wan))
    if b"#GetGenericPortMappingEntry" in req:
        if b"<NewPortMappingIndex>0<" not in req:
            return http(fault(713), "500 Internal Server Error")
        port = "744\u00b9" if MODE == "digits" else "7447"
        desc = f"set by a LAN host {C1}" if MODE == "c1" else "rosnet-tui"
        return http(soap("GetGenericPortMappingEntry", NewRemoteHost="", NewExternalPort=port,
                         NewProtocol="TCP", NewInternalPort="7447",
                         NewInternalClient="10.10.10.1", NewEnabled="1",
                         NewPortMappingDescription=desc, NewLeaseDuration="3600"))
    return http(fault(714), "500 Internal Server Error")


def serve_http() -> None:
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("0.0.0.0", 5000))
    srv.listen(16)
    while True:
        conn, _ = srv.accept()
        with conn:
            conn.settimeout(3)
            data = b""
            try:
                while b"\r\n\r\n" not in data and len(data) < 65536:
                    got = conn.recv(4096)
                    if not got:
                        break
                    data += got
                head, _, body = data.partition(b"\r\n\r\n")
                n = next((int(ln.split(b":")[1]) for ln in head.split(b"\r\n")
                          if ln.lower().startswith(b"content-length")), 0)
                while len(body) < n:
                    got = conn.recv(4096)
                    if not got:
                        break
                    body += got
                conn.sendall(answer(head + b"\r\n\r\n" + body))
            except OSError:
                pass


def serve_ssdp() -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    s.bind(("0.0.0.0", 1900))
    ok = (f"HTTP/1.1 200 OK\r\nST: urn:schemas-upnp-org:device:InternetGatewayDevice:1\r\n"
          f"USN: uuid:hostile-1\r\nLOCATION: http://{GW}:5000/rootDesc.xml\r\n\r\n").encode()
    while True:
        data, addr = s.recvfrom(2048)
        if not data.startswith(b"M-SEARCH"):
            continue
        if MODE == "flood":
            for _ in range(2000):
                s.sendto(b"HTTP/1.1 200 OK\r\nST: junk\r\n\r\n", addr)
        s.sendto(ok, addr)


threading.Thread(target=serve_http, daemon=True).start()
print("ready", flush=True)
serve_ssdp()
