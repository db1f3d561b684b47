"""ROS_MASTER_URI in ~/.bashrc: right for the role, our block only, ROS_IP lines on request."""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rosnet_tui.core.config.settings_model import Peer, RosSettings, Settings, ThisComponent
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files.bashrc import (
    apply_bashrc,
    export_line,
    find_ros_ip_lines,
    master_uri,
    preview_bashrc,
    shell_lines,
)
from rosnet_tui.core.files.hosts import WriterSettingsError

needs_bash = pytest.mark.skipif(not shutil.which("bash"), reason="bash is not installed")


def robot() -> Settings:
    return Settings(this=ThisComponent(name="turtlebot", role="master", local_ip="10.10.10.1",
                                       public_ip="203.0.113.2"),
                    peers=[Peer(name="sami", local_ip="192.168.1.10", public_ip="198.51.100.2")],
                    ros=RosSettings(master="turtlebot", port=11311))


def laptop(port: int = 11311) -> Settings:
    return Settings(this=ThisComponent(name="sami", role="member", local_ip="192.168.1.10"),
                    peers=[Peer(name="turtlebot", local_ip="10.10.10.1",
                                public_ip="203.0.113.2")],
                    ros=RosSettings(master="turtlebot", port=port))


def source(path: Path, *names: str) -> list[str]:
    """Values of *names* after bash sources *path* (unset -> '<unset>')."""
    script = f"source {path} >/dev/null 2>&1; " + "; ".join(
        f'echo "${{{n}-<unset>}}"' for n in names)
    r = subprocess.run(["bash", "--norc", "--noprofile", "-c", script], capture_output=True,
                       text=True, timeout=10, env={"PATH": "/usr/bin:/bin"})
    return r.stdout.splitlines()


# --------------------------------------------------------------------------- the URI
def test_master_uses_its_own_name_never_its_public_ip():
    assert master_uri(robot()) == "http://turtlebot:11311"
    assert "203.0.113.2" not in "\n".join(preview_bashrc(robot(), Path("/nonexistent/x")).diff())


def test_member_uses_the_masters_name_and_port():
    assert master_uri(laptop(port=11312)) == "http://turtlebot:11312"
    assert export_line(laptop()) == "export ROS_MASTER_URI=http://turtlebot:11311"


def test_shell_lines_unset_stray_variables_of_the_current_shell():
    assert shell_lines(laptop(), {"ROS_IP": "192.168.1.10", "HOME": "/x"}) == \
        ["export ROS_MASTER_URI=http://turtlebot:11311", "unset ROS_IP"]
    assert shell_lines(laptop(), {}) == ["export ROS_MASTER_URI=http://turtlebot:11311"]


@pytest.mark.parametrize("mutate, key", [
    (lambda s: setattr(s.ros, "master", ""), "ros.master"),
    (lambda s: setattr(s.ros, "master", "nobody"), "ros.master"),
    (lambda s: setattr(s.ros, "port", 0), "ros.port"),
    (lambda s: setattr(s.this, "name", "sa mi"), "this.name"),
])
def test_bad_settings_write_nothing(tmp_path, mutate, key):
    f = tmp_path / ".bashrc"
    f.write_text("alias ll='ls -l'\n")
    s = laptop()
    mutate(s)
    with pytest.raises(WriterSettingsError) as info:
        apply_bashrc(s, f, state_dir=tmp_path / "state")
    assert key in [k for k, _ in info.value.problems]
    assert f.read_text() == "alias ll='ls -l'\n" and not (tmp_path / "state").exists()


# --------------------------------------------------------------------------- ROS_IP lines
@pytest.mark.parametrize("line, hit", [
    ("export ROS_IP=192.168.1.10", True),
    ("  export ROS_HOSTNAME=sami  # for the LAN", True),
    ("ROS_IP=10.0.0.1", True),
    ("export ROS_IP=$(hostname -I | awk '{print $1}')", True),
    ('export ROS_IP="${MY_IP}";', True),
    ("export ROS_IP", True),
    ("ROS_IP=10.0.0.1 roslaunch pkg x.launch", False),   # only that command's environment
    ("# export ROS_IP=10.0.0.1", False),
    ("export ROS_IPX=1", False),
    ("echo $ROS_IP", False),
])
def test_finds_plain_ros_ip_assignments_only(line, hit):
    assert bool(find_ros_ip_lines(line + "\n")) is hit


def test_ros_ip_lines_are_listed_but_untouched_unless_agreed(tmp_path):
    f, sd = tmp_path / ".bashrc", tmp_path / "state"
    original = b"# mine\nexport ROS_IP=192.168.1.10\r\nexport ROS_HOSTNAME=sami\n"
    f.write_bytes(original)
    p = preview_bashrc(laptop(), f)
    assert len(p.notes) == 2 and all("--comment-ros-ip" in n for n in p.notes)
    assert p.new.startswith(original)
    apply_bashrc(laptop(), f, comment_ros_ip=True, state_dir=sd)
    out = f.read_bytes()
    assert out.startswith(b"# mine\n# rosnet-tui: export ROS_IP=192.168.1.10\r\n"
                          b"# rosnet-tui: export ROS_HOSTNAME=sami\n")
    assert b"commented out ROS_IP/ROS_HOSTNAME" in out
    assert not preview_bashrc(laptop(), f, comment_ros_ip=True).changed  # idempotent
    mf.undo_last(sd)
    assert f.read_bytes() == original


@needs_bash
def test_sourcing_the_result_gives_the_right_environment(tmp_path):
    f = tmp_path / ".bashrc"
    f.write_text("export ROS_MASTER_URI=http://localhost:11311\nexport ROS_IP=192.168.1.10\n")
    apply_bashrc(laptop(), f, comment_ros_ip=True, state_dir=tmp_path / "s")
    assert source(f, "ROS_MASTER_URI", "ROS_IP") == ["http://turtlebot:11311", "<unset>"]


@needs_bash
def test_commenting_never_breaks_the_shell_syntax(tmp_path):
    f = tmp_path / ".bashrc"
    f.write_text("if [ -n \"$ON_LAN\" ]; then\n    export ROS_IP=10.10.10.1\nfi\n")
    apply_bashrc(robot(), f, comment_ros_ip=True, state_dir=tmp_path / "s")
    text = f.read_text()
    assert "    : # rosnet-tui: export ROS_IP=10.10.10.1\n" in text  # an empty `then` is invalid
    assert subprocess.run(["bash", "-n", str(f)], timeout=10).returncode == 0
    assert source(f, "ROS_MASTER_URI", "ROS_IP") == ["http://turtlebot:11311", "<unset>"]


def test_a_later_master_uri_that_overrides_ours_is_noted(tmp_path):
    f = tmp_path / ".bashrc"
    f.write_text(f"{mt.BEGIN_MARKER}\nexport ROS_MASTER_URI=http://x:1\n{mt.END_MARKER}\n"
                 "export ROS_MASTER_URI=http://localhost:11311\n")
    notes = preview_bashrc(laptop(), f).notes
    assert any("overrides it" in n and "line 4" in n for n in notes)


def test_missing_bashrc_is_created_and_undo_removes_it(tmp_path):
    f, sd = tmp_path / "home" / ".bashrc", tmp_path / "state"
    apply_bashrc(robot(), f, state_dir=sd)
    assert "export ROS_MASTER_URI=http://turtlebot:11311" in f.read_text()
    mf.undo_last(sd)
    assert not f.exists()


# --------------------------------------------------------------------------- properties
_RC_LINES = st.sampled_from([
    "# ~/.bashrc", "", "\tcase $- in", "    *i*) ;;", "esac", "alias ll='ls -alF'",
    "export PATH=\"$HOME/.local/bin:$PATH\"", "source /opt/ros/noetic/setup.bash",
    "export ROS_MASTER_URI=http://localhost:11311", "export ROS_IP=192.168.1.10",
    "  export ROS_HOSTNAME=sami # lan", "ROS_IP=1.2.3.4 rosrun x y", "PS1='\\u@\\h:\\w\\$ '",
    "# export ROS_IP=commented", "fe80::1 looks like ipv6",
])


@st.composite
def bashrc_files(draw) -> bytes:
    lines = draw(st.lists(_RC_LINES, max_size=12))
    text = "".join(x + draw(st.sampled_from(["\n", "\r\n"])) for x in lines)
    if text and draw(st.booleans()):
        text = text.rstrip("\r\n")
    return text.encode()


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=bashrc_files(), member=st.booleans(), comment=st.booleans())
def test_generated_bashrc_files_apply_undo_and_idempotence(data, member, comment):
    s = laptop() if member else robot()
    with tempfile.TemporaryDirectory() as d:
        f, sd = Path(d) / ".bashrc", Path(d) / "state"
        f.write_bytes(data)
        found = {c.index: c for c in find_ros_ip_lines(data.decode())}
        first = apply_bashrc(s, f, comment_ros_ip=comment, state_dir=sd)
        once = f.read_bytes()
        assert not apply_bashrc(s, f, comment_ros_ip=comment, state_dir=sd).changed
        assert f.read_bytes() == once
        old = mt.split_lines(data.decode())
        new = mt.split_lines(once.decode())
        for i, line in enumerate(old):
            if comment and i in found:
                assert mt.line_content(new[i]).endswith(line.strip().rstrip("\r"))
                assert "rosnet-tui" in new[i]
                if line.endswith("\n"):  # the line ending is kept
                    assert new[i][len(mt.line_content(new[i])):] == line[len(mt.line_content(line)):]
            elif line.endswith("\n"):
                assert new[i] == line
            else:
                assert mt.line_content(new[i]) == line
        assert f"export ROS_MASTER_URI={master_uri(s)}" in mt.extract_block(once.decode())
        if first.changed:
            mf.undo_last(sd)
        assert f.read_bytes() == data
