"""Shell commands that run a program on a peer over SSH: a stdlib-only one on the peer's
python3 without site, or one fed on stdin to the interpreter of the rosnet-tui installed there
(found by a POSIX sh prelude in the same round trip)."""

from __future__ import annotations

import base64
import shlex

from rosnet_tui.core.peer import zenohproto


def shq(s: str) -> str:
    """*s* quoted for a POSIX shell (single quotes)."""
    return "'" + s.replace("'", "'\\''") + "'"


def python_command(script: str, *args: str, python: str = "python3") -> str:
    """A shell command running stdlib-only *script* with python3 on a peer (no install needed).

    ``-S``: the probes need the standard library only, so the peer skips site (its
    site-packages, .pth files): a faster start, and nothing of the peer's can shadow a module.
    ``-I``: nor can the folder it starts in, nor PYTHON* variables.
    """
    b64 = base64.b64encode(script.encode()).decode()
    quoted = " ".join(shq(a) for a in args)
    return (f"{python} -I -S -c 'import base64;exec(base64.b64decode(\"{b64}\"))' "
            f"{quoted}").strip()


def python_stdin_command(*args: str) -> str:
    """A shell command running the stdlib-only program fed on stdin with python3 on a peer
    (``python3 -I -S -``: isolated, without site, as :func:`python_command`)."""
    return "python3 -I -S - " + " ".join(shlex.quote(a) for a in args)


# The README installs rosnet-tui (with eclipse-zenoh) in a virtual environment of its own; the
# peer's python3 has no eclipse-zenoh (and under PEP 668 pip may not add it). So the Zenoh peer
# program runs with the interpreter of the rosnet-tui installed on the peer, found by this POSIX
# sh prelude in the same SSH round trip: the launchers the README's installs make (pipx, uv tool,
# the root-owned pipx), their virtual environments, the PATH, and last a login shell's PATH
# (bounded by `timeout`: fixed places first). A launcher's interpreter is its first line, or the
# path on its second line in the `#!/bin/sh` form pip and uv write for long paths, or else the
# `python` beside the launcher's target. The program is still fed on stdin, so the version of
# the peer's rosnet-tui does not matter. Nothing here reads stdin: the program must arrive whole.
# It runs from / (the folder an interpreter puts first on its path: one only root may write).
NO_INSTALL_EXIT = 4       # the prelude's exit status when no rosnet-tui is installed on the peer
PEER_INSTALL_PLACES = ("the PATH, ~/.local/bin, pipx's and uv's tool folders, /usr/local/bin, "
                       "/opt/pipx, a login shell's PATH")
README_INSTALL = "sudo apt install -y --no-install-recommends pipx && pipx install --force ."
"""The README's install line without its last part (opening the wizard), typed in a checkout."""
_FIND_INSTALL = r"""
py=; h=${HOME:-~}; d=${XDG_DATA_HOME:-$h/.local/share}
L() {
  [ -f "$1" ] || return 1
  l1=; l2=; { IFS= read -r l1; IFS= read -r l2; } <"$1" 2>/dev/null
  case $l1 in
  "#!/bin/sh"*) r=${l2#*"exec' "}; q=${r%"${r#?}"}; r=${r#?}; p=${r%%"$q"*} ;;
  "#!"*) r=${l1#??}; r=${r#"${r%%[! ]*}"}; p=${r%% *} ;;
  *) p= ;;
  esac
  case $p in */env|*/sh|*/bash) p= ;; /*) ;; *) p= ;; esac
  [ -n "$p" ] && [ -x "$p" ] || p=$(dirname -- "$(readlink -f -- "$1")")/python
  [ -x "$p" ] && py=$p
}
V() { [ -x "$1/rosnet-tui/bin/python" ] && py=$1/rosnet-tui/bin/python; }
for b in "${PIPX_BIN_DIR:-$h/.local/bin}" "${UV_TOOL_BIN_DIR:-${XDG_BIN_HOME:-$h/.local/bin}}"; do
  [ -n "$py" ] || L "$b/rosnet-tui"
done
for v in "${PIPX_HOME:-$d/pipx}/venvs" "$h/.local/pipx/venvs" "${UV_TOOL_DIR:-$d/uv/tools}"; do
  [ -n "$py" ] || V "$v"
done
[ -n "$py" ] || { b=$(command -v rosnet-tui) && L "$b"; }
[ -n "$py" ] || L /usr/local/bin/rosnet-tui || V /opt/pipx/venvs
[ -n "$py" ] || { b=$(timeout 3 "${SHELL:-/bin/sh}" -lc "command -v rosnet-tui" </dev/null \
                     2>/dev/null | tail -n 1) && L "$b"; }
cd / || exit 1     # the interpreter puts its folder first on the path: one only root may write
[ -n "$py" ] && [ -n "$BOOT" ] && exec "$py" -c "$BOOT" "$@"
[ -n "$py" ] && exec "$py" - "$@"
[ -n "$FALLBACK" ] && [ -n "$BOOT" ] && exec python3 -I -S -c "$BOOT" "$@" no-install
[ -n "$FALLBACK" ] && exec python3 -I -S - "$@"
echo "$MARK$NO_INSTALL"
exit @EXIT@
""".replace("@EXIT@", str(NO_INSTALL_EXIT))
NO_INSTALL_REPORT = '{"error": "no_install", "detail": "no rosnet-tui installed"}'
"""What a peer without rosnet-tui installed reports (after the program's mark)."""


def installed_python_command(*args: str, mark: str, fallback: bool = False,
                             boot: str | None = None) -> str:
    """The command running a program fed on stdin on a peer with the interpreter of the
    rosnet-tui installed there (its packages: eclipse-zenoh, paramiko, cryptography), found by
    _FIND_INSTALL; one SSH round trip. Without an installation it prints ``<mark>{"error":
    "no_install", ...}`` and exits NO_INSTALL_EXIT, unless *fallback* (a program that also runs
    on the standard library alone: the peer's python3 runs it then). Run by ``sh -c``, so the
    peer's login shell may be any shell. Never the peer's python3 for a program that needs the
    install's packages. With *boot*, the interpreter runs ``-c boot`` (a loader that reads the
    program from stdin and leaves stdin open: the peer agent's) instead of ``-``."""
    script = ("MARK=" + shq(mark) + "\nNO_INSTALL=" + shq(NO_INSTALL_REPORT) + "\n"
              + ("FALLBACK=1\n" if fallback else "")
              + ("BOOT=" + shq(boot) + "\n" if boot else "") + _FIND_INSTALL)
    return "sh -c " + shq(script) + " rosnet-tui-peer " + " ".join(shq(a) for a in args)


def zenoh_peer_command(*args: str, need_zenoh: bool = True) -> str:
    """The command running the Zenoh peer program (core/peer/zenohproto.py, fed on stdin) on a peer
    with the interpreter of the rosnet-tui installed there (:func:`installed_python_command`).
    Without an installation it prints a ``no_install`` report and exits NO_INSTALL_EXIT, unless
    not *need_zenoh* (``info`` needs only the standard library: the peer's python3 runs it
    then)."""
    return installed_python_command(*args, mark=zenohproto.REPORT_MARK, fallback=not need_zenoh)
