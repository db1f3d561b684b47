"""What sshd offers a user who presents no credentials (SSH ``none`` authentication), with the
standard library alone: the SSH audit's program (core/exposure/outsider.py) runs this on a peer
first, so the audit costs its round trips instead of an interpreter importing paramiko.

It speaks only what OpenSSH offers by default: key exchange curve25519-sha256 (X25519 in pure
Python, RFC 7748) and the cipher chacha20-poly1305@openssh.com (ChaCha20 and Poly1305 in pure
Python, OpenSSH's PROTOCOL.chacha20poly1305). A server offering neither raises
:class:`Unsupported` (the program then asks with paramiko). It authenticates nothing and sends no
secret, so it does not verify the server's host key: the answer is what any stranger gets.
Single file, Python 3.8+, no imports from rosnet_tui (fed to a peer's interpreter as source).
"""
# ruff: noqa: E702, B905

from __future__ import annotations

import hashlib
import os
import struct


class Unsupported(Exception):
    """The server offers neither curve25519 nor chacha20-poly1305."""

P = 2 ** 255 - 19

def x25519(k, u):
    k = bytearray(k); k[0] &= 248; k[31] &= 127; k[31] |= 64
    k = int.from_bytes(k, "little"); x1 = int.from_bytes(u, "little") & ((1 << 255) - 1)
    x2, z2, x3, z3, swap = 1, 0, x1, 1, 0
    for i in range(254, -1, -1):
        b = (k >> i) & 1
        if swap ^ b:
            x2, x3, z2, z3 = x3, x2, z3, z2
        swap = b
        a, bb = x2 + z2, x2 - z2
        aa, b2 = a * a % P, bb * bb % P
        e = aa - b2
        c, d = x3 + z3, x3 - z3
        da, cb = d * a % P, c * bb % P
        x3, z3 = (da + cb) ** 2 % P, x1 * (da - cb) ** 2 % P
        x2, z2 = aa * b2 % P, e * (aa + 121665 * e) % P
    if swap:
        x2, z2 = x3, z3
    return (x2 * pow(z2, P - 2, P) % P).to_bytes(32, "little")

M32 = 0xffffffff

def _block(key, counter, nonce):
    s = [0x61707865, 0x3320646e, 0x79622d32, 0x6b206574, *struct.unpack("<8I", key),
         counter & M32, counter >> 32, *struct.unpack("<2I", nonce)]
    x = s[:]
    def q(a, b, c, d):
        x[a] = (x[a] + x[b]) & M32; x[d] ^= x[a]; x[d] = ((x[d] << 16) | (x[d] >> 16)) & M32
        x[c] = (x[c] + x[d]) & M32; x[b] ^= x[c]; x[b] = ((x[b] << 12) | (x[b] >> 20)) & M32
        x[a] = (x[a] + x[b]) & M32; x[d] ^= x[a]; x[d] = ((x[d] << 8) | (x[d] >> 24)) & M32
        x[c] = (x[c] + x[d]) & M32; x[b] ^= x[c]; x[b] = ((x[b] << 7) | (x[b] >> 25)) & M32
    for _ in range(10):
        q(0, 4, 8, 12); q(1, 5, 9, 13); q(2, 6, 10, 14); q(3, 7, 11, 15)
        q(0, 5, 10, 15); q(1, 6, 11, 12); q(2, 7, 8, 13); q(3, 4, 9, 14)
    return struct.pack("<16I", *((a + b) & M32 for a, b in zip(x, s)))

def chacha(key, nonce, data, counter=0):
    out = bytearray()
    for i in range(0, len(data), 64):
        ks = _block(key, counter + i // 64, nonce)
        out += bytes(a ^ b for a, b in zip(data[i:i + 64], ks))
    return bytes(out)

def poly1305(key, msg):
    r = int.from_bytes(key[:16], "little") & 0x0ffffffc0ffffffc0ffffffc0fffffff
    s, p, acc = int.from_bytes(key[16:], "little"), (1 << 130) - 5, 0
    for i in range(0, len(msg), 16):
        acc = (acc + int.from_bytes(msg[i:i + 16] + b"\x01", "little")) * r % p
    return ((acc + s) & ((1 << 128) - 1)).to_bytes(16, "little")

def sstr(b):
    return struct.pack(">I", len(b)) + b

def mpint(n):
    b = n.to_bytes((n.bit_length() + 8) // 8, "big") if n else b""
    return sstr(b)

class Reader:
    def __init__(self, b):
        self.b, self.i = b, 0
    def take(self, n):
        v = self.b[self.i:self.i + n]; self.i += n
        if len(v) < n:
            raise ValueError("short message")
        return v
    def u32(self):
        return struct.unpack(">I", self.take(4))[0]
    def s(self):
        return self.take(self.u32())

class Conn:
    def __init__(self, sock):
        self.sock, self.buf, self.seq_in, self.seq_out, self.keys = sock, b"", 0, 0, None
    def recv_exact(self, n):
        while len(self.buf) < n:
            d = self.sock.recv(65536)
            if not d:
                raise ConnectionError("the server closed the connection")
            self.buf += d
        v, self.buf = self.buf[:n], self.buf[n:]
        return v
    def line(self):
        while b"\n" not in self.buf:
            d = self.sock.recv(65536)
            if not d or len(self.buf) > 8192:
                raise ConnectionError("no SSH version line")
            self.buf += d
        v, _, self.buf = self.buf.partition(b"\n")
        return v.rstrip(b"\r")
    def send(self, payload):
        nonce = struct.pack(">Q", self.seq_out); self.seq_out += 1
        if self.keys is None:
            pad = 8 - (5 + len(payload)) % 8
            pad += 8 if pad < 4 else 0
            self.sock.sendall(struct.pack(">IB", 1 + len(payload) + pad, pad) + payload
                              + os.urandom(pad))
            return
        main, header = self.keys[0]
        pad = 8 - (1 + len(payload)) % 8
        pad += 8 if pad < 4 else 0
        body = struct.pack(">B", pad) + payload + os.urandom(pad)
        elen = chacha(header, nonce, struct.pack(">I", len(body)))
        ebody = chacha(main, nonce, body, 1)
        tag = poly1305(chacha(main, nonce, bytes(32)), elen + ebody)
        self.sock.sendall(elen + ebody + tag)
    def recv(self):
        nonce = struct.pack(">Q", self.seq_in); self.seq_in += 1
        if self.keys is None:
            n = struct.unpack(">I", self.recv_exact(4))[0]
            if n > 65536:
                raise ValueError("packet too long")
            body = self.recv_exact(n)
        else:
            main, header = self.keys[1]
            elen = self.recv_exact(4)
            n = struct.unpack(">I", chacha(header, nonce, elen))[0]
            if n > 65536:
                raise ValueError("packet too long")
            ebody, tag = self.recv_exact(n), self.recv_exact(16)
            if poly1305(chacha(main, nonce, bytes(32)), elen + ebody) != tag:
                raise ValueError("bad MAC")
            body = chacha(main, nonce, ebody, 1)
        return body[1:len(body) - body[0]]
    def recv_msg(self):
        while True:
            m = self.recv()
            if m[:1] in (b"\x02", b"\x04", b"\x07", b"\x35"):   # ignore, debug, ext-info, banner
                continue
            if m[:1] == b"\x01":
                r = Reader(m[1:]); r.u32()
                raise ConnectionError("the server disconnected: " + r.s().decode(errors="replace"))
            return m

KEX = (b"curve25519-sha256", b"curve25519-sha256@libssh.org")
CIPHER = b"chacha20-poly1305@openssh.com"

def none_methods(sock, user, version=b"SSH-2.0-rosnet_tui_audit"):
    """(the methods sshd offers *user* when asked with "none", the server's version line) on
    the connected *sock*; raises Unsupported (see the module), ConnectionError or ValueError."""
    c = Conn(sock)
    sock.sendall(version + b"\r\n")
    v_s = c.line()
    while not v_s.startswith(b"SSH-"):
        v_s = c.line()
    i_c = (b"\x14" + os.urandom(16) + sstr(b",".join(KEX)) +
           sstr(b"ssh-ed25519,ecdsa-sha2-nistp256,ecdsa-sha2-nistp384,ecdsa-sha2-nistp521,"
                b"rsa-sha2-512,rsa-sha2-256,ssh-rsa") + sstr(CIPHER) * 2 +
           sstr(b"hmac-sha2-256,hmac-sha1") * 2 + sstr(b"none") * 2 + sstr(b"") * 2 +
           b"\x00" + bytes(4))
    c.send(i_c)
    i_s = c.recv_msg()
    if i_s[:1] != b"\x14":
        raise ValueError("no KEXINIT from the server")
    r = Reader(i_s[17:])
    kex, _hk, enc_cs, enc_sc = (r.s().split(b",") for _ in range(4))
    kexalg = next((k for k in KEX if k in kex), None)
    if kexalg is None or CIPHER not in enc_cs or CIPHER not in enc_sc:
        raise Unsupported(f"kex {b','.join(kex).decode()}; ciphers {b','.join(enc_cs).decode()}")
    priv = os.urandom(32)
    q_c = x25519(priv, (9).to_bytes(32, "little"))
    c.send(b"\x1e" + sstr(q_c))
    reply = c.recv_msg()
    if reply[:1] != b"\x1f":
        raise ValueError("no KEX reply")
    r = Reader(reply[1:])
    k_s, q_s = r.s(), r.s()
    k = int.from_bytes(x25519(priv, q_s), "big")
    h = hashlib.sha256(sstr(version) + sstr(v_s) + sstr(i_c) + sstr(i_s) + sstr(k_s) + sstr(q_c)
                       + sstr(q_s) + mpint(k)).digest()
    if c.recv_msg()[:1] != b"\x15":
        raise ValueError("no NEWKEYS from the server")
    c.send(b"\x15")
    def key(letter):
        k1 = hashlib.sha256(mpint(k) + h + letter + h).digest()
        k2 = hashlib.sha256(mpint(k) + h + k1).digest()
        kk = k1 + k2
        return kk[:32], kk[32:]
    c.keys = (key(b"C"), key(b"D"))
    c.send(b"\x05" + sstr(b"ssh-userauth"))
    if c.recv_msg()[:1] != b"\x06":
        raise ValueError("no SERVICE_ACCEPT")
    c.send(b"\x32" + sstr(user.encode()) + sstr(b"ssh-connection") + sstr(b"none"))
    while True:
        m = c.recv_msg()
        if m[:1] == b"\x34":
            return ["none"], v_s.decode(errors="replace")
        if m[:1] == b"\x33":
            methods = Reader(m[1:]).s().decode(errors="replace").split(",")
            return [x for x in methods if x], v_s.decode(errors="replace")
        raise ValueError(f"unexpected SSH message {m[0]}")
