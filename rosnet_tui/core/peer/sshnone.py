"""What sshd offers a user who presents no credentials (SSH ``none`` authentication), with
``cryptography``'s primitives: the SSH audit's program (core/exposure/outsider.py) runs this on a
peer first, under the interpreter of the rosnet-tui installed there, so the audit costs its round
trips and cryptography's import instead of paramiko's.

It speaks only what OpenSSH offers by default: key exchange curve25519-sha256 (X25519) and the
cipher chacha20-poly1305@openssh.com (ChaCha20 and Poly1305 as OpenSSH's
PROTOCOL.chacha20poly1305 puts them together). A server offering neither raises
:class:`Unsupported` (the program then asks with paramiko). It authenticates nothing and sends no
secret, so it does not verify the server's host key: the answer is what any stranger gets.
Single file, no imports from rosnet_tui (fed to a peer's interpreter as source); cryptography is
imported when a connection is asked, so importing this module for its path costs nothing.
"""

from __future__ import annotations

import hashlib
import os
import socket
import struct


class Unsupported(Exception):
    """The server offers neither curve25519 nor chacha20-poly1305."""


def chacha20(key, seq, data, counter=0):
    """*data* XOR OpenSSH's ChaCha20 stream: a 64-bit block counter and the packet's 64-bit
    sequence number as nonce. cryptography's 16-byte nonce is the cipher's last four state words
    (little-endian): the counter's eight bytes, then the sequence number's (big-endian, as sent)."""
    from cryptography.hazmat.primitives.ciphers import Cipher, algorithms

    nonce = struct.pack("<Q", counter) + struct.pack(">Q", seq)
    return Cipher(algorithms.ChaCha20(key, nonce), mode=None).encryptor().update(data)


def poly1305_key(main, seq):
    """The packet's Poly1305 key: the first 32 bytes of the main key's stream at block 0."""
    return chacha20(main, seq, bytes(32))


def sstr(b):
    return struct.pack(">I", len(b)) + b


def mpint(n):
    b = n.to_bytes((n.bit_length() + 8) // 8, "big") if n else b""
    return sstr(b)


def padding(n):
    """The random padding's length for a packet of *n* bytes before it (4 to 11 bytes, up to a
    multiple of 8)."""
    pad = 8 - n % 8
    return pad + 8 if pad < 4 else pad


class Reader:
    def __init__(self, b):
        self.b = b
        self.i = 0

    def take(self, n):
        v = self.b[self.i:self.i + n]
        self.i += n
        if len(v) < n:
            raise ValueError("short message")
        return v

    def u32(self):
        return struct.unpack(">I", self.take(4))[0]

    def s(self):
        return self.take(self.u32())


class Conn:
    def __init__(self, sock):
        self.sock = sock
        self.buf = b""
        self.seq_in = 0
        self.seq_out = 0
        self.keys = None   # ((main, header) to the server, (main, header) from it)

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
        seq = self.seq_out
        self.seq_out += 1
        if self.keys is None:
            pad = padding(5 + len(payload))
            self.sock.sendall(struct.pack(">IB", 1 + len(payload) + pad, pad) + payload
                              + os.urandom(pad))
            return
        from cryptography.hazmat.primitives.poly1305 import Poly1305

        main, header = self.keys[0]
        pad = padding(1 + len(payload))
        body = struct.pack(">B", pad) + payload + os.urandom(pad)
        elen = chacha20(header, seq, struct.pack(">I", len(body)))
        ebody = chacha20(main, seq, body, 1)
        tag = Poly1305.generate_tag(poly1305_key(main, seq), elen + ebody)
        self.sock.sendall(elen + ebody + tag)

    def recv(self):
        seq = self.seq_in
        self.seq_in += 1
        if self.keys is None:
            n = struct.unpack(">I", self.recv_exact(4))[0]
            if n > 65536:
                raise ValueError("packet too long")
            body = self.recv_exact(n)
        else:
            from cryptography.exceptions import InvalidSignature
            from cryptography.hazmat.primitives.poly1305 import Poly1305

            main, header = self.keys[1]
            elen = self.recv_exact(4)
            n = struct.unpack(">I", chacha20(header, seq, elen))[0]
            if n > 65536:
                raise ValueError("packet too long")
            ebody = self.recv_exact(n)
            tag = self.recv_exact(16)
            try:
                Poly1305.verify_tag(poly1305_key(main, seq), elen + ebody, tag)
            except InvalidSignature:
                raise ValueError("bad MAC") from None
            body = chacha20(main, seq, ebody, 1)
        return body[1:len(body) - body[0]]

    def recv_msg(self):
        while True:
            m = self.recv()
            if m[:1] in (b"\x02", b"\x04", b"\x07", b"\x35"):   # ignore, debug, ext-info, banner
                continue
            if m[:1] == b"\x01":
                r = Reader(m[1:])
                r.u32()
                raise ConnectionError("the server disconnected: " + r.s().decode(errors="replace"))
            return m


KEX = (b"curve25519-sha256", b"curve25519-sha256@libssh.org")
CIPHER = b"chacha20-poly1305@openssh.com"


def none_methods(sock, user, version=b"SSH-2.0-rosnet_tui_audit"):
    """(the methods sshd offers *user* when asked with "none", the server's version line) on
    the connected *sock*; raises Unsupported (see the module), ConnectionError or ValueError."""
    from cryptography.hazmat.primitives.asymmetric.x25519 import (
        X25519PrivateKey,
        X25519PublicKey,
    )

    try:  # NEWKEYS and the next message go out back to back: with Nagle's algorithm the second
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)  # waited for the server's
    except OSError:                                     # delayed ACK (40 ms on Linux)
        pass
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
    priv = X25519PrivateKey.generate()
    q_c = priv.public_key().public_bytes_raw()   # public_bytes() would import serialization: 25 ms
    c.send(b"\x1e" + sstr(q_c))
    reply = c.recv_msg()
    if reply[:1] != b"\x1f":
        raise ValueError("no KEX reply")
    r = Reader(reply[1:])
    k_s, q_s = r.s(), r.s()
    # a bad point or an all-zero secret raises ValueError, as any misread reply does
    k = int.from_bytes(priv.exchange(X25519PublicKey.from_public_bytes(q_s)), "big")
    h = hashlib.sha256(sstr(version) + sstr(v_s) + sstr(i_c) + sstr(i_s) + sstr(k_s) + sstr(q_c)
                       + sstr(q_s) + mpint(k)).digest()
    if c.recv_msg()[:1] != b"\x15":
        raise ValueError("no NEWKEYS from the server")
    c.send(b"\x15")

    def key(letter):
        # 64 bytes: the main key (payload, Poly1305 key), then the header key (packet length)
        k1 = hashlib.sha256(mpint(k) + h + letter + h).digest()
        k2 = hashlib.sha256(mpint(k) + h + k1).digest()
        return k1, k2

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
