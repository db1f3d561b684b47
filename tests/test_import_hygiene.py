"""The core never imports Textual: the CLI and the tests use it without a UI."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import rosnet_tui.core


def test_core_imports_no_textual():
    modules = [f"rosnet_tui.core.{m.name}" for m in pkgutil.walk_packages(
        rosnet_tui.core.__path__) if not m.name.startswith("_")]
    modules += ["rosnet_tui.core.checks"]
    code = (
        "import importlib, sys\n"
        f"mods = {modules!r}\n"
        "from rosnet_tui.core.checks import load_builtin_checks\n"
        "for m in mods: importlib.import_module(m)\n"
        "load_builtin_checks()\n"
        "bad = sorted(m for m in sys.modules if m == 'textual' or m.startswith('textual.'))\n"
        "print(bad)\n"
        "sys.exit(1 if bad else 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr


def test_headless_cli_does_not_load_textual():
    code = ("import sys\nfrom rosnet_tui.cli import build_parser\nbuild_parser()\n"
            "sys.exit(1 if 'textual' in sys.modules else 0)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr


ROOT = __import__("pathlib").Path(__file__).resolve().parents[1]


def test_layering_contracts_hold():
    """pyproject's [tool.importlinter] contracts: core apart from UI/CLI, rules apart from checks,
    check modules independent of each other."""
    import shutil

    exe = shutil.which("lint-imports")
    assert exe, "import-linter is a test dependency (pip install -e .[test])"
    out = subprocess.run([exe, "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout


# rosproto.py is one stdlib-only file on purpose: it is piped to peers over SSH as it is.
_SIZE_EXEMPT = {"rosnet_tui/core/peer/rosproto.py"}


def test_no_source_file_is_over_650_lines():
    big = {}
    for path in sorted((ROOT / "rosnet_tui").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > 650 and rel not in _SIZE_EXEMPT:
            big[rel] = n
    assert not big, f"split these files (600 lines is the aim, 650 the limit): {big}"


# --------------------------------------------------------------------------- function-level imports
# An import inside a function is allowed for one reason: start-up cost (a heavy library or a big
# part of the program kept off the path of `rosnet-tui --help`, the wizard's first screen and the
# peers' programs). Never to dodge an import circle: remove the circle instead. Keyed by
# (file, imported module); a new function-level import fails the test until it is listed here.
FUNCTION_LEVEL_IMPORTS: dict[tuple[str, str], str] = {
    ("rosnet_tui/cli/__init__.py", "rosnet_tui.cli.wizard"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/__init__.py", "rosnet_tui.cli"): "start-up cost: the warm process's client (rosnet_tui.cli.warm) only for the commands it serves",
    ("rosnet_tui/cli/__init__.py", "rosnet_tui.cli.check"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/warm.py", "subprocess"): "start-up cost: only a cold run starting a warm process needs it, not a served one",
    ("rosnet_tui/cli/check.py", "rosnet_tui.core.checks.runner"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/check.py", "rosnet_tui.core.advisor"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/check.py", "rich.console"): "start-up cost: rich kept off the start-up path",
    ("rosnet_tui/cli/check.py", "rich.markup"): "start-up cost: rich kept off the start-up path",
    ("rosnet_tui/cli/check.py", "rich.table"): "start-up cost: rich kept off the start-up path",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.config.paths"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.files.cut_writes"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.files.managed_write"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.files.privilege"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.net.netinfo"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.saved.settings"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/common.py", "rosnet_tui.core.config.settings_model"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/report.py", "rosnet_tui.cli.common"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/report.py", "rosnet_tui.core.saved.settings"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/report.py", "rosnet_tui.core.net.netinfo"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/report.py", "rosnet_tui.cli.check"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/ros.py", "rosnet_tui.core.ros"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/ros.py", "asyncio"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/ros_pair.py", "rosnet_tui.core.sync.pin"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/ros_pair.py", "rosnet_tui.core.sync.signing"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "asyncio"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.pin"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.loop"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.outcome"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.service"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.status"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.sync.signing"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/units.py", "rosnet_tui.core.files.regular_file"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/units.py", "rosnet_tui.core.saved.settings"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.saved.settings"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/sync.py", "rosnet_tui.core.ssh.options"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/undo.py", "rosnet_tui.cli.common"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "rosnet_tui.core.saved.settings"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "rosnet_tui.core.config.settings_model"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "asyncio"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "rosnet_tui.core.config.paths"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "rosnet_tui.core.wizard.session"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/wizard.py", "rosnet_tui.ui.app"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/writing.py", "rosnet_tui.core.net.netinfo"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/cli/writing.py", "rosnet_tui.core.checks.runner"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/core/advisor/__main__.py", "argparse"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/peer/agentproto.py", "traceback"): "start-up cost: a program fed to peers over SSH loads only what its run needs",
    ("rosnet_tui/core/checks/__init__.py", "importlib"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/checks/__init__.py", "pkgutil"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/checks/probes/listening.py", "psutil"): "start-up cost: psutil kept off the start-up path",
    ("rosnet_tui/core/checks/rosbridge.py", "websockets.asyncio.client"): "start-up cost: websockets kept off the start-up path",
    ("rosnet_tui/core/checks/rosbridge.py", "websockets.exceptions"): "start-up cost: websockets kept off the start-up path",
    ("rosnet_tui/core/ros/fleet_tls.py", "cryptography.hazmat.primitives.asymmetric"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/ros/fleet_tls.py", "cryptography.hazmat.primitives"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/ros/fleet_tls.py", "cryptography"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/ros/fleet_tls.py", "cryptography.x509.oid"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/net/http.py", "ssl"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/net/http.py", "email.message"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/net/http.py", "requests"): "start-up cost: requests kept off the start-up path (without a character detector: core/net/lazy_import.py)",
    ("rosnet_tui/core/net/netinfo.py", "psutil"): "start-up cost: psutil kept off the start-up path",
    ("rosnet_tui/core/exposure/outsider.py", "cryptography"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/exposure/outsider.py", "cryptography.hazmat.primitives"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/exposure/outsider.py", "cryptography.hazmat.primitives.asymmetric"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/exposure/outsider.py", "cryptography.x509.oid"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/peer/sshnone.py", "cryptography.exceptions"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/peer/sshnone.py", "cryptography.hazmat.primitives.asymmetric.x25519"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/peer/sshnone.py", "cryptography.hazmat.primitives.ciphers"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/peer/sshnone.py", "cryptography.hazmat.primitives.poly1305"): "start-up cost: cryptography kept off the start-up path",
    ("rosnet_tui/core/ros/pairing.py", "asyncio"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/ros/pairing.py", "copy"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/ros/pairing.py", "threading"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/wizard/report.py", "tomlkit"): "start-up cost: tomlkit kept off the start-up path",
    ("rosnet_tui/core/peer/rosproto.py", "base64"): "start-up cost: a program fed to peers over SSH loads only what its run needs",
    ("rosnet_tui/core/peer/rosproto.py", "xml.parsers"): "start-up cost: a program fed to peers over SSH loads only what its run needs",
    ("rosnet_tui/core/saved/settings.py", "tomlkit"): "start-up cost: tomlkit kept off the start-up path",
    ("rosnet_tui/core/ssh/connection.py", "paramiko"): "start-up cost: paramiko kept off the start-up path (without invoke: core/net/lazy_import.py)",
    ("rosnet_tui/core/ssh/origin.py", "psutil"): "start-up cost: psutil kept off the start-up path",
    ("rosnet_tui/core/ssh/session.py", "paramiko"): "start-up cost: paramiko kept off the start-up path",
    ("rosnet_tui/core/files/undo_journal.py", "shutil"): "start-up cost: stdlib module loaded when used",
    ("rosnet_tui/core/peer/zenohproto.py", "zenoh"): "start-up cost: zenoh kept off the start-up path",
    ("rosnet_tui/core/peer/tunnelproto.py", "paramiko"): "start-up cost: paramiko kept off the peer agent's start (it loads this every ROS 2 round)",
    ("rosnet_tui/core/ros/relay.py", "zenoh"): "start-up cost: zenoh kept off the start-up path",
    ("rosnet_tui/cli/relay.py", "rosnet_tui.core.ros"): "start-up cost: a subcommand's core is loaded when it runs, not for --help",
    ("rosnet_tui/ui/app.py", "textual.filter"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/app.py", "rosnet_tui.ui.setup_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "asyncio"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "signal"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "threading"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "os"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "termios"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "rosnet_tui.ui.advisor_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/app.py", "rosnet_tui.ui.help_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/setup_screen.py", "rosnet_tui.core.saved.ui_state"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/step_screen.py", "rosnet_tui.ui.mdlite"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.checks.data"): "start-up cost: the checks package is loaded with the first result, not for the first screen",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.upnp.forwards"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/step_screen.py", "rosnet_tui.ui.map_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/step_screen.py", "rosnet_tui.ui.write_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/step_screen.py", "rosnet_tui.ui.trust_screen"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/terminal.py", "os"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/terminal.py", "textual"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/terminal.py", "textual.drivers.linux_driver"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/terminal.py", "rosnet_tui.ui"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/terminal.py", "rosnet_tui.ui.keys"): "start-up cost: loaded when the screen or feature is used",
    ("rosnet_tui/ui/textual_compat.py", "textual.keys"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/textual_compat.py", "textual._xterm_parser"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/textual_compat.py", "textual.drivers"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/ui/theme.py", "textual.scrollbar"): "start-up cost: textual kept off the start-up path",
    ("rosnet_tui/core/files/cut_writes.py", "rosnet_tui.core.jsonsafe"): "start-up cost: every run's look for cut writes (before --help too) imports nothing beyond os; json only when a journal is found",
    ("rosnet_tui/core/saved/settings.py", "rosnet_tui.core.files.managed_write"): "start-up cost: the writer (hashlib, secrets, shlex: 17 modules) loads on the first save, not to read the settings at start",
    ("rosnet_tui/core/ros/ros2.py", "rosnet_tui.core.files"): "start-up cost: the writers (difflib, hashlib: 19 modules) load to write ROS 2's files, not for a step's text",
    ("rosnet_tui/core/ros/ros2.py", "rosnet_tui.core.files.hosts"): "start-up cost: the writers (difflib, hashlib: 19 modules) load to write ROS 2's files, not for a step's text",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.advisor"): "start-up cost: the advisor's rules load with the first verdict, not for the first screen",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.checks.runner"): "start-up cost: the runner and the checks' libraries (74 modules) load when checks run, not for the first screen",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.exposure.router_card"): "start-up cost: the router card (psutil, netifaces) loads when it is shown",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.net.netinfo"): "start-up cost: psutil and netifaces load when the local network is first read",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.ssh.known_hosts"): "start-up cost: hashlib, hmac and base64 load when a host key is trusted",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.sync.status"): "start-up cost: the sync package (its stores, dnspython) loads when its text is shown",
    ("rosnet_tui/core/upnp/modem.py", "rosnet_tui.core.net.netinfo"): "start-up cost: netifaces and psutil load when the modem is searched for, not when the Router step is drawn",
    ("rosnet_tui/core/wizard/session.py", "rosnet_tui.core.wizard.write_plans"): "start-up cost: the write plans and their writers load when `w` is pressed",
    ("rosnet_tui/core/wizard/steps.py", "rosnet_tui.core.exposure"): "start-up cost: the firewall (psutil, netifaces, the writers: 60 modules) loads for the Linux step's text, not the first screen's",
    ("rosnet_tui/core/wizard/steps.py", "rosnet_tui.core.exposure.router_card"): "start-up cost: the router card (psutil, netifaces, the writers: 62 modules) loads for the Router step's text",
    ("rosnet_tui/core/wizard/steps.py", "rosnet_tui.core.files.hosts"): "start-up cost: the hosts writer (difflib, hashlib: 29 modules) loads for the Linux step's text",
    ("rosnet_tui/core/wizard/steps.py", "rosnet_tui.core.ros"): "start-up cost: ROS 2's module (json, datetime: 11 modules) loads for a ROS 2 step's text only",
    ("rosnet_tui/core/sync/choose_store.py", ".dnsstore"): "start-up cost: dnspython, for DNS store users only",
    ("rosnet_tui/core/sync/store.py", ".signing"): "start-up cost: cryptography, loaded when records are read (`sync status` reads no store)",
    ("rosnet_tui/screenshots.py", "rosnet_tui.core.wizard.session"): "start-up cost: textual and the UI, loaded when screenshots are taken",
    ("rosnet_tui/screenshots.py", "rosnet_tui.ui.app"): "start-up cost: textual and the UI, loaded when screenshots are taken",
}


def _function_level_imports() -> set[tuple[str, str]]:
    import ast

    found: set[tuple[str, str]] = set()
    for path in sorted((ROOT / "rosnet_tui").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()

        def walk(node: ast.AST, in_function: bool, rel: str = rel) -> None:
            for child in ast.iter_child_nodes(node):
                inner = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                          ast.Lambda))
                if in_function and isinstance(child, ast.ImportFrom):
                    found.add((rel, "." * child.level + (child.module or "")))
                elif in_function and isinstance(child, ast.Import):
                    found.update((rel, a.name) for a in child.names)
                elif (in_function and isinstance(child, ast.Call)   # core/net/lazy_import.py
                      and getattr(child.func, "id", None) == "import_without" and child.args
                      and isinstance(child.args[0], ast.Constant)):
                    found.add((rel, str(child.args[0].value)))
                walk(child, inner)

        walk(ast.parse(path.read_text(encoding="utf-8")), False)
    return found


def test_every_function_level_import_has_a_start_up_reason():
    found = _function_level_imports()
    unlisted = sorted(found - set(FUNCTION_LEVEL_IMPORTS))
    assert not unlisted, ("imports inside a function, not in FUNCTION_LEVEL_IMPORTS with their "
                          "start-up reason (an import circle is removed, not dodged): "
                          + ", ".join(f"{f}: {m}" for f, m in unlisted))
    assert all(why.startswith("start-up cost") for why in FUNCTION_LEVEL_IMPORTS.values())


def test_the_allow_lists_hold_no_stale_entry():
    found = _function_level_imports()
    stale = sorted(set(FUNCTION_LEVEL_IMPORTS) - found)
    assert not stale, f"listed but gone (remove them from the lists): {stale}"


def test_sync_and_checks_import_each_other_at_module_level_only():
    """The sync <-> checks loop is gone: the watcher asks core.public_ip, the applier reads hosts
    lines with core.hosts, linux.resolve reads the applied records from saved.sync_applied."""
    found = _function_level_imports()
    crossing = sorted((f, m) for f, m in found
                      if (f.startswith("rosnet_tui/core/sync/") and "core.checks" in m)
                      or (f.startswith("rosnet_tui/core/checks/") and "core.sync" in m))
    assert not crossing, crossing
