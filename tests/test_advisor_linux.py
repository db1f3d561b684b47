"""The advisor's Linux rules: names, ping, SSH, the chats between peers."""

from __future__ import annotations

from rosnet_tui.core.advisor import advice_by_check
from tests.advisor_support import (
    chat,
    fresh_names,
    icmp_filtered,
    ids,
    loopback,
    only,
    run,
    ssh,
    ssh_shut_out,
    text,
    unreachable,
    wrong,
)
from tests.builders import healthy_laptop, laptop_settings, put


def test_name_wrong_names_the_hosts_line():
    f = only(run(wrong()[0]), "linux.name.wrong")
    assert "`203.0.113.99 turtlebot`" in text(f) and "`203.0.113.2 turtlebot`" in text(f)
    assert set(f.check_ids) == {"linux.hosts", "linux.resolve"}
    # resolver wrong while the hosts file is right: look elsewhere
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = "192.0.2.200"
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    f = only(run(r), "linux.name.wrong")
    assert "nsswitch" in text(f) and f.check_ids == ["linux.resolve"]


def test_name_loopback_names_the_127_line():
    fs = run(loopback()[0])
    f = only(fs, "linux.name.loopback")
    assert "127.0.1.1" in text(f) and "`192.168.1.10 sami`" in text(f)
    assert "linux.name.wrong" not in ids(fs)


def test_ping_filtered_is_info_not_failure():
    f = only(run(icmp_filtered()[0]), "linux.ping.icmp_filtered")
    assert f.severity == "info" and "Not a problem" in f.meaning


def test_peer_unreachable_collects_the_failing_checks():
    fs = run(unreachable()[0])
    f = only(fs, "linux.peer.unreachable")
    assert set(f.check_ids) == {"linux.ping", "linux.ssh", "linux.chat_out", "linux.chat_in"}
    assert "10.10.10.1" in text(f)   # the peer's local IP, for its forwarding
    assert "linux.chat.both_fail" not in ids(fs)


def test_ssh_host_key_changed_says_verify_then_keygen_r():
    f = only(run(ssh("host_key_changed")()[0]), "linux.ssh.host_key_changed")
    t = text(f)
    assert "SHA256:NEWKEY" in t and "ssh-keygen -R turtlebot" in t
    assert "intercepting" in f.meaning and "out of band" in t
    assert t.index("Verify") < t.index("ssh-keygen -R")


def test_ssh_failures_are_told_apart():
    for failure, rule_id, needle in (("auth", "linux.ssh.auth", "ssh-copy-id root@turtlebot"),
                                     ("sshd", "linux.ssh.sshd", "systemctl enable --now ssh"),
                                     ("network", "linux.peer.unreachable", "forwards TCP 22")):
        fs = run(ssh(failure)()[0])
        assert needle in text(only(fs, rule_id)), failure
        others = {"linux.ssh.auth", "linux.ssh.sshd", "linux.peer.unreachable"} - {rule_id}
        assert not others & set(ids(fs)), failure


def test_chat_one_way_blames_the_right_side():
    f = only(run(chat(True, False)()[0]), "linux.chat.in_fails")
    assert "sami's modem" in text(f) and "192.168.1.10" in text(f)     # ours
    f = only(run(chat(False, True)()[0]), "linux.chat.out_fails")
    assert "turtlebot's modem" in text(f) and "10.10.10.1" in text(f)  # the peer's


def test_chat_failure_kinds_get_their_own_fix():
    r, s = chat(True, False)()
    r["linux.chat_in"].data["peers"]["turtlebot"]["failure"] = "peer_resolve"
    f = only(run(r, s), "linux.chat.in_fails")
    assert "On turtlebot: add `198.51.100.2 sami` to /etc/hosts" in text(f)
    r, s = chat(False, True)()
    r["linux.chat_out"].data["peers"]["turtlebot"]["failure"] = "wrong_peer"
    f = only(run(r, s), "linux.chat.out_fails")
    assert "another machine answers" in f.meaning and "10.10.10.1" in text(f)


def test_chats_that_failed_for_lack_of_ssh_belong_to_the_ssh_finding():
    r, s = ssh("auth")()
    put(r, "linux.chat_out", "fail", peers={"turtlebot": {"ok": False, "failure": "ssh:auth"}})
    put(r, "linux.chat_in", "fail", peers={"turtlebot": {"ok": False, "failure": "ssh:auth"}})
    fs = run(r, s)
    assert [f.rule for f in fs if f.severity == "fail"] == ["linux.ssh.auth"]
    assert only(fs, "linux.ssh.auth").check_ids == ["linux.ssh", "linux.chat_out",
                                                    "linux.chat_in"]
    # a peer without an SSH user is not a chat failure either
    r = healthy_laptop()
    put(r, "linux.chat_out", "skip", peers={"turtlebot": {"ok": False, "failure": "no_user"}})
    put(r, "linux.chat_in", "pass", peers={"turtlebot": {"ok": False, "failure": "no_user"}})
    assert not [f for f in run(r) if f.rule.startswith("linux.chat")]


def test_peer_unreachable_tells_ping_answering_modem_from_silence():
    r = ssh_shut_out(healthy_laptop(), None)
    f = only(run(r), "linux.peer.unreachable")
    assert "answers ping" in f.meaning and "modem is online" in f.meaning
    assert f.actions[0].startswith("Check that turtlebot's modem forwards TCP 22")
    # silence at a stale address: the hosts line first
    r, s = wrong()
    ssh_shut_out(r, None, icmp=False)
    fs = run(r, s)
    f = only(fs, "linux.peer.unreachable")
    assert "Nothing answers at 203.0.113.99" in f.meaning
    assert "settings say turtlebot is at 203.0.113.2" in f.meaning
    assert f.actions[0].startswith("Check our hosts line")
    assert ids(fs).index("linux.name.wrong") < ids(fs).index("linux.peer.unreachable")
    # a peer we chatted with is reachable, whatever port 22 says
    r = healthy_laptop()
    put(r, "linux.ping", "pass", peers={"turtlebot": {"icmp": True, "tcp22": False}})
    assert "linux.peer.unreachable" not in ids(run(r))


def test_a_stale_address_sync_cannot_follow_names_sync_pin():
    """A peer whose sync_key is not pinned (linux.resolve's ``unpinned``): sync never follows
    its address, and the action says which command fixes that (issue 35)."""
    r, s = wrong()
    ssh_shut_out(r, None, icmp=False)
    assert "sync pin" not in only(run(r, s), "linux.peer.unreachable").actions[0]
    put(r, "linux.resolve", "fail", unpinned=["turtlebot"])
    act = only(run(r, s), "linux.peer.unreachable").actions[0]
    assert "once turtlebot's sync key is pinned here (`rosnet-tui sync pin turtlebot`)" in act


def test_peer_unreachable_on_a_lan_profile_does_not_talk_about_modems():
    r, _ = unreachable()
    s = laptop_settings(profile="office")
    f = only(run(r, s), "linux.peer.unreachable")
    assert "office LAN" in f.meaning and "modem" not in text(f)
    assert "must print 10.10.10.1" in text(f)


# --------------------------------------------------------------------------- a fresh install
def test_a_name_that_does_not_resolve_is_titled_so_and_explains_what_failed_for_it():
    """Issue 29 (section 4, row 4): on a fresh install no name resolves. The finding is titled
    "does not resolve" (not "resolves to the wrong address"), and it explains the checks that
    failed for that reason alone, linux.hosts included: none is left without a rule."""
    fs = run(fresh_names())
    un = [f for f in fs if f.rule == "linux.name.unresolved"]
    assert [f.condition for f in un] == ["a name does not resolve"] * 2, ids(fs)
    assert "linux.name.wrong" not in ids(fs)
    tb = next(f for f in un if f.meaning.startswith("turtlebot"))
    assert "turtlebot does not resolve on sami: /etc/hosts has no line for it" in tb.meaning
    assert "`203.0.113.2 turtlebot`" in text(tb) and "rosnet-tui hosts apply" in text(tb)
    assert set(tb.check_ids) == {"linux.resolve", "linux.hosts", "linux.ping", "linux.ssh",
                                 "linux.chat_out", "linux.chat_in"}
    assert "check.unexplained" not in ids(fs), [f.meaning for f in fs]
    advice = advice_by_check(fs)
    assert [f.rule for f in advice["linux.hosts"]] == ["linux.name.unresolved"] * 2


def test_a_name_missing_from_the_hosts_file_that_dns_answers_wrong():
    r = healthy_laptop()
    put(r, "linux.hosts", "fail", missing=["turtlebot"])
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = "192.0.2.200"
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    fs = run(r)
    f = only(fs, "linux.name.wrong")
    assert set(f.check_ids) == {"linux.hosts", "linux.resolve"}
    assert "has no line for turtlebot, so DNS answers 192.0.2.200" in text(f)
    assert "looks right" not in text(f) and "check.unexplained" not in ids(fs)


def test_a_name_the_hosts_file_has_but_the_resolver_does_not_read():
    r = healthy_laptop()
    r["linux.resolve"].data["names"]["turtlebot"]["resolved"] = None
    put(r, "linux.resolve", "fail", wrong=["turtlebot"])
    f = only(run(r), "linux.name.unresolved")
    assert f.check_ids == ["linux.resolve"] and "nsswitch.conf" in text(f)
