"""SshSession.wait() must return the command's whole output, not only what had arrived when the
exit status did (issue 25's linux.ssh flake: "exit status 0" but no marker in the output).

sshd sends the exit status when it reaps the command, which may be before it has read and sent
everything the command wrote to its stdout: the channel's output ends at EOF, not at the exit
status. A background writer that outlives the shell makes that ordering certain here.
"""

from __future__ import annotations

from rosnet_tui.core.checks.probes.agents import why_no_report
from rosnet_tui.core.ssh.session import ssh_run


async def test_output_written_after_the_exit_status_is_kept(ssh_client):
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(),
                        "(sleep 0.4; echo late-marker) & echo early; exit 0", timeout=10)
    assert res.ok and res.exit_status == 0
    assert res.stdout == "early\nlate-marker\n", res.stdout


async def test_a_quick_command_never_loses_its_output(ssh_client):
    missing = 0
    for _ in range(25):
        res = await ssh_run(ssh_client.opts(), ssh_client.peer(),
                            "echo rosnet-tui-ssh-ok", timeout=10)
        assert res.ok and res.exit_status == 0
        missing += "rosnet-tui-ssh-ok" not in res.stdout
    assert missing == 0


async def test_output_that_comes_with_the_end_is_kept(ssh_client, monkeypatch):
    """The pump looked at the buffer, then at the channel's state: output and the end that came
    between the two looks were dropped (CI: a pairing answer lost, "gave no answer (exit status
    1)"). Here each look at the buffer, while the channel is open, lasts until it has closed."""
    import paramiko

    real, looked = paramiko.Channel.recv_ready, []

    def recv_ready(chan):
        if not looked:                        # the first look: the answer and the end come now
            looked.append(chan)
            for _ in range(500):              # at most 5 s: the command ends within 0.3 s
                if chan.closed:
                    break
                chan.status_event.wait(0.01)
            return False
        return real(chan)

    monkeypatch.setattr(paramiko.Channel, "recv_ready", recv_ready)
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(),
                        "sleep 0.3; echo the-answer; exit 1", timeout=10)
    assert res.exit_status == 1 and res.stdout == "the-answer\n", res


async def test_input_the_command_never_took_is_named(ssh_client):
    """A command fed on stdin that ends before its input is sent: the result says how much
    went (a peer program cut short runs silently, its report missing with "exit status 0")."""
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(), "exit 0",
                        stdin=b"#" * 20_000_000, timeout=10)
    assert res.exit_status == 0
    assert " of the 20000000 bytes of its input were sent" in res.detail, res.detail
    whole = await ssh_run(ssh_client.opts(), ssh_client.peer(), "cat >/dev/null",
                          stdin=b"#" * 100_000, timeout=10)
    assert whole.exit_status == 0 and "input" not in whole.detail, whole.detail


async def test_a_program_without_its_report_says_what_it_left(ssh_client):
    """"gave no report" names what came instead: stderr's last lines, else the end of the
    output, else "no output"; and how the command ended."""
    said = {}
    for cmd in ("echo ROSNET_SSHAUDIT-cut; exit 0", "exit 0", "echo oops >&2; exit 1"):
        said[cmd] = why_no_report(await ssh_run(ssh_client.opts(), ssh_client.peer(), cmd,
                                                timeout=10))
    assert said["echo ROSNET_SSHAUDIT-cut; exit 0"] == (
        "its output ends 'ROSNET_SSHAUDIT-cut'; ran on localhost as root, exit status 0"), said
    assert said["exit 0"] == "no output; ran on localhost as root, exit status 0", said
    assert said["echo oops >&2; exit 1"].startswith("oops; "), said


async def test_a_connection_that_breaks_before_the_output_ends_is_named(ssh_client):
    """sshd sends the exit status when the command ends, its output after: the connection
    dying in between left "exit status 0" and a part of the output, read as whole. The command
    here ends at once; what it left behind kills its sshd before writing the rest (0.9 s later:
    after the exit status, within the 1 s the session waits for the output's end after it)."""
    res = await ssh_run(ssh_client.opts(), ssh_client.peer(),
                        "p=$PPID; (sleep 0.9; kill -9 $p; sleep 0.2; echo late) & "
                        "echo early; exit 0", timeout=10)
    assert res.exit_status == 0 and res.stdout == "early\n", res
    assert "the SSH connection broke before its output ended" in res.detail, res.detail
