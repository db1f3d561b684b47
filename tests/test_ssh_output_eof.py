"""SshSession.wait() must return the command's whole output, not only what had arrived when the
exit status did (issue 25's linux.ssh flake: "exit status 0" but no marker in the output).

sshd sends the exit status when it reaps the command, which may be before it has read and sent
everything the command wrote to its stdout: the channel's output ends at EOF, not at the exit
status. A background writer that outlives the shell makes that ordering certain here.
"""

from __future__ import annotations

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
