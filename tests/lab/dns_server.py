"""The lab's resolver: a tiny authoritative UDP DNS server (run inside the internet namespace).

    python dns_server.py --listen 192.0.2.53 --record probe.lab.test=192.0.2.10 [...]

Known names get their A record; every other name gets NXDOMAIN at once, so nothing in the lab
waits on a resolver that is not there.
"""

from __future__ import annotations

import argparse
import signal
import socket
import sys

import dns.flags
import dns.message
import dns.rcode
import dns.rdataclass
import dns.rdatatype
import dns.rrset


def answer(wire: bytes, records: dict[str, str]) -> bytes | None:
    try:
        query = dns.message.from_wire(wire)
    except Exception:
        return None
    response = dns.message.make_response(query)
    response.flags |= dns.flags.AA
    if not query.question:
        response.set_rcode(dns.rcode.FORMERR)
        return response.to_wire()
    q = query.question[0]
    name = q.name.to_text(omit_final_dot=True).lower()
    if name not in records:
        response.set_rcode(dns.rcode.NXDOMAIN)
    elif q.rdtype == dns.rdatatype.A and q.rdclass == dns.rdataclass.IN:
        response.answer.append(dns.rrset.from_text(q.name, 60, "IN", "A", records[name]))
    return response.to_wire()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--listen", required=True)
    parser.add_argument("--port", type=int, default=53)
    parser.add_argument("--record", action="append", default=[], metavar="NAME=IP")
    args = parser.parse_args(argv)
    records = {}
    for item in args.record:
        name, _, ip = item.partition("=")
        records[name.lower().rstrip(".")] = ip
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((args.listen, args.port))
    print(f"lab dns listening on {args.listen}:{args.port}", flush=True)
    while True:
        wire, peer = sock.recvfrom(4096)
        reply = answer(wire, records)
        if reply is not None:
            sock.sendto(reply, peer)


if __name__ == "__main__":
    try:
        raise SystemExit(main())
    except KeyboardInterrupt:
        raise SystemExit(0) from None
