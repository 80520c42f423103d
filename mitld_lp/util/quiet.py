"""Native libraries kept off standard output.

Storm's C++ logger and HiGHS's banner ("Running HiGHS ...") write to the process's file
descriptor 1, under Python's ``sys.stdout``, so neither ``-q`` nor ``--json`` could keep
them out of the answer.  :func:`native_quiet` sends descriptor 1 to a temporary file
for the duration of a native call; afterwards each line written there goes to the
debug log under the library's name (``-v`` on the command line shows them).  The
descriptor is the process's: what another thread prints to stdout meanwhile is logged
the same way, so calls are serialised and kept short (the command line prints nothing
while a solver or a world loader runs).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

__all__ = ["native_quiet"]

log = logging.getLogger("mitld_lp.native")

_QUIET = threading.RLock()

#: The longest line of a library's output kept in the log.
LINE = 200


def _flush_c_streams() -> None:
    """Flush C's stdio buffers (where C++'s ``std::cout`` goes), so that what a library
    wrote lands in the capture and not on the terminal later."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def native_quiet(library: str) -> Iterator[None]:
    """Run the block with file descriptor 1 sent to a temporary file, then log what
    ``library`` wrote there at debug level, a line at a time (at most :data:`LINE`
    characters each).  Nested blocks capture once."""
    with _QUIET:
        with contextlib.suppress(ValueError, OSError):
            sys.stdout.flush()
        try:
            saved = os.dup(1)
        except OSError:  # no standard output at all: nothing to protect
            yield
            return
        with tempfile.TemporaryFile() as sink:
            _flush_c_streams()
            os.dup2(sink.fileno(), 1)
            try:
                yield
            finally:
                _flush_c_streams()
                os.dup2(saved, 1)
                os.close(saved)
                sink.seek(0)
                for line in sink.read().decode("utf-8", "replace").splitlines():
                    if line.strip():
                        text = line if len(line) <= LINE else line[:LINE] + "..."
                        log.debug("%s: %s", library, text)
