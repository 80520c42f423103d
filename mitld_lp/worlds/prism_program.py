"""Storm's messages and output, made one line and kept off standard output.

* :func:`storm_error`: one of Storm's exceptions as one line naming the file, and the
  line where Storm's message gives it (a parse error quotes at most :data:`EXCERPT`
  characters of the file).
* :func:`storm_quiet`: Storm's C++ logger writes to the process's standard output; this
  sends file descriptor 1 elsewhere during a Storm call, so that nothing but the
  program's answer reaches stdout (the lines go to the debug log).

Every error is a :class:`mitld_lp.worlds.WorldError`, one line.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import re
import sys
import tempfile
import threading
from collections.abc import Iterator

from mitld_lp.worlds import WorldError

__all__ = ["storm_error", "storm_quiet", "excerpt", "EXCERPT"]

log = logging.getLogger("mitld_lp.worlds.prism")

EXCERPT = 24
"""At most this many characters of a user's file are quoted in a message."""



def excerpt(text: str, limit: int = EXCERPT) -> str:
    """``text`` on one line, cut to ``limit`` characters (``...`` marks a cut)."""
    flat = " ".join(text.split())
    return flat if len(flat) <= limit else flat[: limit - 3] + "..."


# --------------------------------------------------------------------------- Storm's errors


_CLASS = re.compile(r"^\s*[A-Za-z]+Exception:\s*")
_PARSE = re.compile(r"Parsing error at (\d+):(\d+):\s*(.*?),?\s*here:[ \t]*\n\t?([^\n]*)")
_AT_LINE = re.compile(r"^Error in .*?, line (\d+):\s*(.*)$")


def storm_error(exc: BaseException, where: str) -> WorldError:
    """Storm's exception ``exc`` as a :class:`WorldError` of one line.

    A parse error becomes ``FILE:LINE:COLUMN: PRISM parse error: expecting X at "..."``
    (an excerpt of the file at the position); ``Error in FILE, line N: ...`` becomes
    ``FILE:N: ...``.  Anything else is Storm's first line, cut to a reasonable length."""
    text = _CLASS.sub("", str(exc).strip())
    m = _PARSE.search(text)
    if m:
        line, column, reason, quoted = int(m[1]), int(m[2]), m[3].strip(), m[4]
        near = quoted[column - 1 :] if 0 < column <= len(quoted) + 1 else quoted
        at = f" at {excerpt(near)!r}" if near.strip() else " at the end of the line"
        return WorldError(f"{where}:{line}:{column}: PRISM parse error: {reason}{at}")
    first = text.splitlines()[0] if text else type(exc).__name__
    m = _AT_LINE.match(first)
    if m:
        return WorldError(f"{where}:{m[1]}: {excerpt(m[2], 200)}")
    return WorldError(f"{where}: Storm: {excerpt(first, 200)}")


# --------------------------------------------------------------------------- Storm's output


_QUIET = threading.Lock()


def _flush_c_streams() -> None:
    """Flush C's stdio buffers (where C++'s ``std::cout`` goes), so that what Storm
    wrote lands in the capture and not on the terminal later."""
    with contextlib.suppress(OSError, AttributeError, TypeError):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def storm_quiet() -> Iterator[None]:
    """Run the block with file descriptor 1 (standard output) sent to a temporary file;
    afterwards the lines Storm wrote there go to the debug log.  Storm's logger prints
    its errors and warnings on stdout, which must carry nothing but the answer."""
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
                        log.debug("storm: %s", excerpt(line, 200))
