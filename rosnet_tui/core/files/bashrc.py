"""ROS settings in ~/.bashrc: a managed block exporting ROS_MASTER_URI for this component's role.

Master: ``http://<its own name>:<port>``; its hosts file maps that name to its local IP (roscore
refuses its public IP). Member: ``http://<the master's name>:<port>``, which its hosts file maps
to the master's public IP (remote) or LAN address (office, portable).

``ROS_IP`` / ``ROS_HOSTNAME`` lines outside our block are found and, only when the user agrees,
commented out (never deleted): on a remote network they override the names in the hosts files.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
from collections.abc import Mapping, Sequence
from pathlib import Path

from rosnet_tui.core.config.paths import default_bashrc_path
from rosnet_tui.core.config.settings_model import Settings
from rosnet_tui.core.files import managed_file as mf
from rosnet_tui.core.files import managed_text as mt
from rosnet_tui.core.files import managed_write as mw
from rosnet_tui.core.files.hosts import WriterSettingsError
from rosnet_tui.core.printable import printable

ROS_IP_REASON = (
    "on a remote network ROS_IP and ROS_HOSTNAME override the names in the hosts files: this "
    "component would advertise an address its peers cannot reach, and topics would flow one way "
    "only (publish but not subscribe, or the reverse)")
_TAG = "rosnet-tui"
_VALUE = r"""(?:\$\(.*\)|`[^`\n]*`|"[^"\n]*"|'[^'\n]*'|[^\s;#'"`]*)"""
_ROS_VAR_RE = re.compile(
    rf"^\s*(?:export\s+|declare\s+-x\s+|typeset\s+-x\s+)?(ROS_IP|ROS_HOSTNAME)={_VALUE}"
    r"\s*;?\s*(?:#.*)?$")
_ROS_EXPORT_ONLY_RE = re.compile(r"^\s*export\s+(ROS_IP|ROS_HOSTNAME)\s*;?\s*(?:#.*)?$")
_COMMENTED_RE = re.compile(rf"^[ \t]*(?::[ \t]*)?# {_TAG}: .*ROS_(?:IP|HOSTNAME)\b", re.MULTILINE)
_MASTER_URI_RE = re.compile(rf"^\s*(?:export\s+)?ROS_MASTER_URI=({_VALUE})")





def ros_problems(settings: Settings) -> list[tuple[str, str]]:
    """Why ROS_MASTER_URI cannot be written from *settings* (empty: it can)."""
    relevant = re.compile(r"^(this\.(name|role)|ros\.(master|port)|peer\[\d+\]\.name)$")
    out = [(k, why) for k, why in settings.problems() if relevant.match(k)]
    if not out and not settings.master_name:
        out.append(("ros.master", "the name of the ROS master is not set"))
    return out


def master_uri(settings: Settings) -> str:
    """The ROS_MASTER_URI this component needs (raises WriterSettingsError on bad settings)."""
    problems = ros_problems(settings)
    if problems:
        raise WriterSettingsError(problems)
    name = settings.this.name if settings.is_master else settings.master_name
    return f"http://{name}:{settings.ros.port}"


def export_line(settings: Settings) -> str:
    """The one line to paste into the current shell: ``export ROS_MASTER_URI=...``."""
    return f"export ROS_MASTER_URI={shlex.quote(master_uri(settings))}"


def shell_lines(settings: Settings, env: Mapping[str, str]) -> list[str]:
    """Lines that fix the current shell (*env*): the export, and an unset of ROS_IP/ROS_HOSTNAME."""
    out = [export_line(settings)]
    stray = [v for v in ("ROS_IP", "ROS_HOSTNAME") if env.get(v)]
    if stray:
        out.append("unset " + " ".join(stray))
    return out


def render_bashrc_block(settings: Settings, *, commented: int = 0) -> list[str]:
    """The lines of our block (between the markers); *commented*: lines we commented out."""
    uri = master_uri(settings)
    if settings.is_master:
        who = (f"this component ({settings.this.name}) runs the ROS master; its own name, "
               "which /etc/hosts maps to its local IP")
    else:
        who = (f"this component ({settings.this.name}) is a member; the master is "
               f"{settings.master_name}, by name (see /etc/hosts)")
    lines = [
        "# Managed by rosnet-tui: edits inside this block are replaced.",
        f"# ROS master: {printable(who)}",
        f"export ROS_MASTER_URI={shlex.quote(uri)}",
    ]
    if commented:
        lines.append(f"# {_TAG} commented out ROS_IP/ROS_HOSTNAME line(s) above: they override "
                     "the hosts-file names on a remote network")
    return lines


def find_ros_ip_lines(text: str | None) -> list[mt.LineChange]:
    """``ROS_IP`` / ``ROS_HOSTNAME`` assignments outside our block, each with its commented form.

    Only plain assignments are touched (not ``ROS_IP=x cmd``, nor continued lines). When a plain
    comment would break the file's syntax (the line is the only one in an ``if``), the line
    becomes the no-op ``:`` followed by the comment.
    """
    lines = mt.split_lines(text or "")
    span = mt.find_block(lines)
    out = []
    for i, line in enumerate(lines):
        if span and span[0] <= i <= span[1]:
            continue
        content = mt.line_content(line)
        m = _ROS_VAR_RE.match(content) or _ROS_EXPORT_ONLY_RE.match(content)
        if not m:
            continue
        out.append(mt.LineChange(i, content, f"# {_TAG}: {content}",
                                 f"sets {m.group(1)}: {ROS_IP_REASON}"))
    return out


def master_uri_overrides(text: str | None) -> list[tuple[int, str]]:
    """ROS_MASTER_URI assignments after our block (they would win over ours): (lineno, line)."""
    lines = mt.split_lines(text or "")
    span = mt.find_block(lines)
    start = span[1] + 1 if span else len(lines)
    return [(i + 1, mt.line_content(x)) for i, x in enumerate(lines) if i >= start
            and _MASTER_URI_RE.match(mt.line_content(x))]


def _indent(line: str) -> str:
    return line[:len(line) - len(line.lstrip())]


def _syntax_ok(data: bytes) -> bool | None:
    """``bash -n`` on *data*: True/False, or None when bash is not available."""
    bash = shutil.which("bash")
    if not bash:
        return None
    try:
        r = subprocess.run([bash, "-n"], input=data, capture_output=True, timeout=5)
    except (OSError, subprocess.TimeoutExpired):
        return None
    return r.returncode == 0


def _guard_syntax(old: bytes | None, body: Sequence[str],
                  changes: list[mt.LineChange]) -> list[mt.LineChange]:
    """Keep a shell file that parsed before parsing after (comment -> ``: # ...`` if needed)."""
    if not changes or old is None or _syntax_ok(old) is not True:
        return changes
    text = mt.decode(old)

    def compose(cs: list[mt.LineChange]) -> bytes:
        return mt.encode(mt.compose_block(text, body, position="end",
                                          replace_lines={c.index: c.new for c in cs}))

    if _syntax_ok(compose(changes)) is not False:
        return changes
    safe = [mt.LineChange(c.index, c.old, f"{_indent(c.old)}: # {_TAG}: {c.old.strip()}", c.why)
            for c in changes]
    return safe if _syntax_ok(compose(safe)) is not False else changes


def preview_bashrc(settings: Settings, path: Path | None = None, *,
                   comment_ros_ip: bool = False, state_dir: Path | None = None) -> mf.Preview:
    """Preview our ROS block at the end of *path* (default ~/.bashrc); writes nothing.

    ROS_IP/ROS_HOSTNAME lines are listed in the notes; with *comment_ros_ip* (only after the user
    agreed) they are commented out.
    """
    path = Path(path) if path is not None else default_bashrc_path()
    old = mw.read_bytes(path, state_dir=state_dir)
    text = mt.decode(old) if old is not None else None
    found = find_ros_ip_lines(text)
    earlier = len(_COMMENTED_RE.findall(text or ""))
    body = render_bashrc_block(settings,
                               commented=earlier + (len(found) if comment_ros_ip else 0))
    notes = []
    if comment_ros_ip:
        found = _guard_syntax(old, body, found)
    for c in found:
        then = (f"it becomes '{c.new.strip()}'" if comment_ros_ip
                else "agree to comment it out (--comment-ros-ip) or remove it by hand")
        notes.append(f"line {c.lineno} '{c.old.strip()}' {c.why}; {then}")
    for lineno, line in master_uri_overrides(text):
        notes.append(f"line {lineno} '{line.strip()}' comes after our block and overrides it; "
                     "remove it by hand")
    replace = {c.index: c.new for c in found} if comment_ros_ip else None
    return mf.preview_block(path, body, position="end", label=f"ROS_MASTER_URI in {path.name}",
                            notes=notes, replace_lines=replace, new_mode=0o644,
                            current=old, use_current=True)


def apply_bashrc(settings: Settings, path: Path | None = None, *, comment_ros_ip: bool = False,
                 expect_digest: str | None = None,
                 state_dir: Path | None = None) -> mf.ApplyResult:
    """Preview and write in one go; *expect_digest* (from an earlier preview) guards staleness."""
    preview = preview_bashrc(settings, path, comment_ros_ip=comment_ros_ip, state_dir=state_dir)
    if expect_digest is not None and preview.digest != expect_digest:
        raise mt.StalePreviewError(f"{preview.path} changed since the preview; nothing was written")
    return mf.apply_preview(preview, state_dir=state_dir)
