"""`python slow_writer.py ARGS` = `rosnet-tui ARGS`, except that the safe writer stops between
the fsync of its temp file and the rename over the target (the delicate moment of an atomic
write) and says so on stdout; a test kills it there with SIGKILL."""

from __future__ import annotations

import sys
import time

from rosnet_tui.cli import main
from rosnet_tui.core.files import managed_write as mw

MARK = "ROSNET-TEST: about to rename"


def _pause() -> None:
    print(MARK, flush=True)
    time.sleep(60)  # bounded: the test kills us long before


if __name__ == "__main__":
    mw._before_rename = _pause
    sys.exit(main(sys.argv[1:]))
