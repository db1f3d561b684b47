"""Pairing over SSH, run in this process against a real sshd on loopback whose forced command
plays the other side's answer (issue 36: the verdicts on each answer, where mutation testing
sees them). A member's pair_over_ssh: signed and installed, refused, no answer, no rosnet-tui
there, an answer for another key. The master's repair_members: request, sign, install, each
refusal named per member."""

from __future__ import annotations

import asyncio
import json
import shlex
import time

import pytest

from rosnet_tui.core.ros import fleet_tls, pairing
from tests.builders import ros2_master, ros2_member

REQ, INST = "rosnet-tui-peer 'request'", "rosnet-tui-peer 'install'"   # as fleet_tls.py is run


def answer_with(ssh_client, tmp_path, by_command: dict[str, str], status: int = 0,
                before: str = "") -> None:
    """The sshd runs a script for any command: it keeps what it was sent (stdin in
    ``got.stdin``, the command in ``got.cmd``, the last one's), runs *before*, prints the answer
    whose key is in the command asked for, and exits *status*."""
    parts = []
    for i, (key, text) in enumerate(by_command.items()):
        f = tmp_path / f"answer{i}"
        f.write_text(text)
        parts.append(f"*{shlex.quote(key)}*) cat {shlex.quote(str(f))};;")
    script = tmp_path / "answer.sh"
    got = shlex.quote(str(tmp_path / "got"))
    script.write_text(f'cat >{got}.stdin\nprintf %s "$SSH_ORIGINAL_COMMAND" >{got}.cmd\n{before}\n'
                      'case "$SSH_ORIGINAL_COMMAND" in\n' + "\n".join(parts)
                      + f"\nesac\nexit {status}\n")
    ssh_client.sshd.authorized.write_text(f'command="sh {script}" {ssh_client.pub}\n')


def sent(tmp_path) -> tuple[str, str]:
    """What the other side was sent last: (stdin, command)."""
    return (tmp_path / "got.stdin").read_text(), (tmp_path / "got.cmd").read_text()


def member_settings(ssh_client):
    s = ros2_member()
    s.ros.master = "localhost"
    s.peers = [ssh_client.peer()]
    return s


def report(d: dict) -> str:
    return "noise\n" + fleet_tls.REPORT_PREFIX + json.dumps(d) + "\n"


def pair(s, paths, ssh_client):
    return asyncio.run(pairing.pair_over_ssh(s, paths, ssh_client.opts(), timeout=10.0))


def test_a_member_installs_what_the_master_signed(ssh_client, tmp_path):
    master = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(ros2_master(), master)
    mine = fleet_tls.tls_paths(tmp_path / "s")
    req = fleet_tls.make_request(mine, "sami")        # the key pair_over_ssh will use
    ca, cert = fleet_tls.sign_request(master, req, master="turtlebot", members=["sami"])
    answer_with(ssh_client, tmp_path, {"--serve": report(
        {"ca": ca, "cert": cert, "sync_key": "ssh-ed25519 AAAAkey"})})
    res = pair(member_settings(ssh_client), mine, ssh_client)
    assert res.ok and res.summary["cn"] == "sami", res.detail
    stdin, cmd = sent(tmp_path)                  # its own request, for its own name
    assert fleet_tls.key_fingerprint(fleet_tls.load_request_key(stdin)) == \
        fleet_tls.key_fingerprint(fleet_tls.load_request_key(req))
    assert cmd == pairing.serve_command("sami")
    assert res.detail.startswith(f"paired with localhost's fleet CA: {mine.node_crt} names sami")
    assert res.master_sync_key == "ssh-ed25519 AAAAkey" and res.seconds > 0
    assert pairing.needs_pairing(ros2_member(), mine) is None
    answer_with(ssh_client, tmp_path, {"--serve": report({"ca": ca, "cert": cert,
                                                          "sync_key": 5})})
    assert pair(member_settings(ssh_client), mine, ssh_client).master_sync_key == ""


@pytest.mark.parametrize("answer, status, why", [
    (report({"error": "no, thanks"}), 1, "localhost did not sign: no, thanks"),
    ("just words\n", 3, "localhost gave no answer (exit status 3: c | d | e)"),
    ('ROSNET_ZENOH {"error": "no_install"}\n', 0, "localhost has no rosnet-tui installed"),
    (report({"ca": "x", "cert": "y"}), 0, "the answer from localhost was not installed"),
    (report({"cert": "y"}), 0, "was not installed"),
])
def test_a_member_says_why_it_is_not_paired(ssh_client, tmp_path, answer, status, why):
    mine = fleet_tls.tls_paths(tmp_path / "s")
    answer_with(ssh_client, tmp_path, {"--serve": answer}, status,
                before="printf 'a\\nb\\nc\\nd\\ne\\n' >&2")
    res = pair(member_settings(ssh_client), mine, ssh_client)
    assert res.ok is False and why in res.detail, res.detail
    assert not mine.node_crt.exists() and 0 < res.seconds < 30


def test_a_member_pairs_only_with_a_master_it_can_reach(ssh_client, tmp_path):
    mine = fleet_tls.tls_paths(tmp_path / "s")
    s = member_settings(ssh_client)
    s.peers[0].ssh_user = ""
    res = pair(s, mine, ssh_client)
    assert not res.ok and "no SSH user for the master localhost" in res.detail
    assert not mine.dir.exists()                       # nothing made
    res = pair(ros2_master(), mine, ssh_client)
    assert res.ok is False and "it signs, it does not pair" in res.detail
    res = pair(s, mine, ssh_client)
    assert res.ok is False
    answer_with(ssh_client, tmp_path, {"--serve": report({"error": "late"})}, before="sleep 20")
    t0 = time.monotonic()
    res = asyncio.run(pairing.pair_over_ssh(member_settings(ssh_client), mine, ssh_client.opts(),
                                            timeout=1.0))
    assert res.ok is False and time.monotonic() - t0 < 10 and "late" not in res.detail
    ssh_client.sshd.authorized.write_text("")          # the master does not let us in
    res = pair(member_settings(ssh_client), mine, ssh_client)
    assert not res.ok and "SSH to localhost failed" in res.detail, res.detail


# --------------------------------------------------------------------------- the master's side
def test_the_master_repairs_each_member_with_its_own_key(ssh_client, tmp_path):
    s = ros2_master()
    peer = ssh_client.peer()
    s.peers = [peer]
    master = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(s, master)
    theirs = fleet_tls.tls_paths(tmp_path / "peer")
    req = fleet_tls.make_request(theirs, "localhost")
    ca, cert = fleet_tls.sign_request(master, req, master="turtlebot", members=["localhost"])
    summ = fleet_tls.cert_summary(cert.encode())
    answer_with(ssh_client, tmp_path, {REQ: report({"csr": req}),
                                       INST: report({"installed": summ})})
    got = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(), 10.0))
    assert got == [("localhost", True, f"valid until {summ['not_after'][:10]}")]
    stdin, cmd = sent(tmp_path)                  # the master's own program, and what to install
    assert stdin.encode() == pairing.FLEET_TLS_SOURCE
    assert cmd.startswith(pairing.tls_command("install", "x")[:-len(" 'install' 'x'")])
    installed = cmd.split("rosnet-tui-peer ", 1)[1]
    assert installed.count(fleet_tls.PEM_CERT) == 2 and "'install' " in installed
    pems = fleet_tls.split_pems(installed.replace("'", "\n"))
    assert len(pems) == 2 and fleet_tls.load_cert(pems[1]).public_key() == \
        fleet_tls.load_request_key(req)
    answer_with(ssh_client, tmp_path, {REQ: report({"error": "x"})})     # the request only
    asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(), 10.0))
    assert sent(tmp_path)[1].endswith("rosnet-tui-peer 'request' 'localhost'")
    answer_with(ssh_client, tmp_path, {REQ: report({"csr": req})}, before="sleep 20")
    t0 = time.monotonic()
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        1.0))
    assert not ok and time.monotonic() - t0 < 10, why
    answer_with(ssh_client, tmp_path, {REQ: report({"csr": req})},
                before="case \"$SSH_ORIGINAL_COMMAND\" in *install*) sleep 20;; esac")
    t0 = time.monotonic()
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        1.0))
    assert not ok and time.monotonic() - t0 < 10, why
    # refusals, each named with its member
    answer_with(ssh_client, tmp_path, {REQ: report({"csr": req}),
                                       INST: report({"error": "disk full"})})
    assert asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(), 10.0)) \
        == [("localhost", False, "disk full")]
    answer_with(ssh_client, tmp_path, {REQ: report({"error": "no key"})})
    assert asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(), 10.0)) \
        == [("localhost", False, "no key")]
    answer_with(ssh_client, tmp_path, {REQ: "nothing\n"}, 4,
                before="printf 'a\\nb\\nc\\nd\\ne\\n' >&2")
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        10.0))
    assert not ok and why == "localhost gave no answer (exit status 4: c | d | e)", why
    answer_with(ssh_client, tmp_path, {REQ: 'ROSNET_ZENOH {"error": "no_install"}\n'})
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        10.0))
    assert not ok and "has no rosnet-tui installed" in why
    stranger = fleet_tls.make_request(fleet_tls.tls_paths(tmp_path / "x"), "bob")
    answer_with(ssh_client, tmp_path, {REQ: report({"csr": stranger})})
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        10.0))
    assert not ok and "bob is not a member" in why
    peer.ssh_user = ""
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        10.0))
    assert not ok and "no SSH user in the settings" in why
    ssh_client.sshd.authorized.write_text("")
    peer.ssh_user = ssh_client.peer().ssh_user
    [(_, ok, why)] = asyncio.run(pairing.repair_members(s, master, [peer], ssh_client.opts(),
                                                        10.0))
    assert not ok and why.startswith("SSH to localhost failed"), why


# --------------------------------------------------------------------------- renewal
def test_a_member_renews_a_certificate_that_expires_soon(ssh_client, tmp_path):
    master = fleet_tls.tls_paths(tmp_path / "m")
    pairing.prepare_master(ros2_master(), master)
    mine = fleet_tls.tls_paths(tmp_path / "s")
    fleet_tls.issue_test_cert(master, mine, "sami", days=10)
    s = member_settings(ssh_client)
    s.ros.security = "mtls"
    answer_with(ssh_client, tmp_path, {"--serve": report({"error": "not now"})})
    said, nxt = pairing.renew_due(s, mine, ssh_client.opts())
    assert said == ["TLS: renewing (the certificate expires in 10 days): localhost did not "
                    "sign: not now"] and nxt == 600.0
    ca, cert = fleet_tls.sign_request(master, fleet_tls.make_request(mine, "sami"),
                                      master="turtlebot", members=["sami"])
    answer_with(ssh_client, tmp_path, {"--serve": report({"ca": ca, "cert": cert})})
    said, nxt = pairing.renew_due(s, mine, ssh_client.opts())
    assert len(said) == 1 and said[0].startswith(
        "TLS: renewing (the certificate expires in 10 days): paired with localhost's") \
        and nxt == 6 * 3600.0, said
    assert mine.node_crt.read_text() == cert
    assert pairing.renew_due(s, mine, ssh_client.opts()) == ([], 6 * 3600.0)   # good now
