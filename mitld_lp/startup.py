"""What must happen before anything heavy is imported.

Started as the command line (``mitld-lp``, or ``python -m mitld_lp`` while Python locates
the module and ``sys.argv[0]`` is ``"-m"``), a Ctrl-C during the package's import prints
one line and exits 130 instead of a traceback; :func:`mitld_lp.cli.run` hands Ctrl-C back
to Python's own handling once it is imported (its command thread then reacts to it).
A program that imports the package is left alone.
"""

from __future__ import annotations

import os
import signal
import sys

__all__ = ["started_as_command"]


def started_as_command() -> bool:
    """Whether this process is the command line, judged from ``sys.argv[0]``."""
    first = sys.argv[0] if sys.argv else ""
    return os.path.basename(first) == "mitld-lp" or first == "-m"


def _interrupted(_signum: int, _frame: object) -> None:
    os.write(2, b"mitld-lp: interrupted\n")
    os._exit(130)


if started_as_command():
    signal.signal(signal.SIGINT, _interrupted)
