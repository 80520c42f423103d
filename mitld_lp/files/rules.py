"""The rules for files a user names, in a module that imports nothing of the package (so
that every reader may use it): :class:`OutputPathError`, and the bounded readers.

Every file the package *reads* on a user's word (a fit's data, a sweep's results, a
controller file) goes through :func:`read_bytes`, :func:`read_text` or
:func:`open_archive`: it is opened only if it is a regular file (a FIFO would block for
ever, ``/dev/zero`` never ends, and both are refused without waiting), and read only up
to a ceiling (:func:`read_limit`, derived from the memory budget), the size checked
before the first byte is read.  :func:`check_zip` checks a zip archive's declared sizes
(and a NumPy member's declared shape) before anything is inflated.  The writing rule and
the writers are in :mod:`mitld_lp.files.write`, which re-exports these names.
"""

from __future__ import annotations

import contextlib
import os
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import IO, TYPE_CHECKING

if TYPE_CHECKING:
    import zipfile

__all__ = [
    "OutputPathError",
    "kernel_folder",
    "InputFileError",
    "read_limit",
    "irregular_kind",
    "open_regular",
    "read_bytes",
    "read_text",
    "check_zip",
    "open_archive",
]

PathLike = str | os.PathLike[str]


class OutputPathError(ValueError):
    """An output path that cannot be written: names the path and why."""


def kernel_folder(folder: Path) -> str | None:
    """``/proc`` or ``/sys`` when ``folder`` (resolved) is in one of them."""
    real = Path(os.path.realpath(folder))
    for kernel in ("/proc", "/sys"):
        if real == Path(kernel) or Path(kernel) in real.parents:
            return kernel
    return None


class InputFileError(OutputPathError, OSError):
    """A file the user gave that is not read: not a regular file, larger than the
    ceiling, or an archive whose declared sizes are too large.  The message names the
    file; ``strerror`` says why without the name, as an ``OSError``'s does, so that a
    reader's ``except OSError`` reports it as it reports a missing file.  (Also an
    :class:`OutputPathError`, so that every caller that maps a bad path to a user error
    maps this one too.)"""

    def __init__(self, label: str, reason: str) -> None:
        super().__init__(f"{label}: {reason}")
        self.strerror = reason


_MIN_LIMIT = 16 << 20
"""The smallest read ceiling (16 MB), whatever the memory budget."""


def _physical_memory() -> int:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 16 << 30


def read_limit(max_memory: int | None = None, *, share: int = 64) -> int:
    """The most bytes of one input file to read: ``max_memory / share`` (default: half
    the machine's memory, as the product's budget), at least 16 MB.  Parsing a text
    file into Python objects takes tens of bytes per byte read, hence the share."""
    budget = _physical_memory() // 2 if max_memory is None else int(max_memory)
    return max(budget // share, _MIN_LIMIT)


def _kind_of(mode: int) -> str:
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def irregular_kind(path: PathLike) -> str | None:
    """What ``path`` is when it exists and is no regular file (``"a FIFO (named pipe)"``,
    ``"a directory"``, ...; a symlink is followed); None for a regular file or no file.
    For a reader that finds files by name (Python's import) and would only say "not
    found"."""
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    return None if stat.S_ISREG(mode) else _kind_of(mode)


def open_regular(path: PathLike, what: str = "") -> IO[bytes]:
    """``path`` opened for reading in binary mode, if it is a regular file (a symlink
    is followed).  Opened without blocking, so that a FIFO is refused rather than
    waited on.  Raises :class:`InputFileError` (not a regular file) or ``OSError``."""
    text = os.fspath(path)
    label = f"{what} {text}" if what else text
    fd = os.open(text, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputFileError(label, f"is {_kind_of(mode)}, not a regular file")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def _too_large(label: str, size: int, limit: int) -> InputFileError:
    return InputFileError(label, f"{_size(size)}, more than the {_size(limit)} read from one "
                          "input file (1/64 of the memory budget: raise --max-memory, or "
                          "give a smaller file)")


def _size(n: float) -> str:
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n:.0f} bytes"


def read_bytes(path: PathLike, limit: int | None = None, what: str = "") -> bytes:
    """The bytes of the regular file ``path`` (:func:`open_regular`), refused before any
    is read when its size is over ``limit`` (default :func:`read_limit`); a file that
    grows past the limit while it is read is refused too.  Raises
    :class:`InputFileError` or ``OSError``."""
    limit = read_limit() if limit is None else limit
    text = os.fspath(path)
    label = f"{what} {text}" if what else text
    with open_regular(path, what) as handle:
        size = os.fstat(handle.fileno()).st_size
        if size > limit:
            raise _too_large(label, size, limit)
        # in pieces: asking read() for limit + 1 bytes at once allocates that much
        chunks, total = [], 0
        while total <= limit:
            chunk = handle.read(min(max(size - total, 0) + 1, _CHUNK, limit + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    if total > limit:
        raise _too_large(label, total, limit)
    return b"".join(chunks)


_CHUNK = 1 << 24
"""Bytes asked of one read of :func:`read_bytes` at most."""


def read_text(path: PathLike, limit: int | None = None, what: str = "", *,
              encoding: str = "utf-8") -> str:
    """:func:`read_bytes` decoded (``UnicodeDecodeError`` when it is not ``encoding``);
    line ends are kept as they are (as ``newline=""``)."""
    return read_bytes(path, limit, what).decode(encoding)


def check_zip(handle: IO[bytes], limit: int, what: str) -> None:
    """Refuse a zip archive (an open binary file, left at its start) whose members
    declare more than ``limit`` bytes once inflated, before anything is inflated (the
    central directory is read; :mod:`zipfile` holds each member to its declared size).
    A NumPy member's (``.npy``) header is read too: an array whose shape asks for more
    bytes than the member holds is refused before NumPy allocates it.  Raises
    :class:`InputFileError` naming ``what``; a file that is no zip archive is left to
    the reader to refuse."""
    import zipfile  # here: a process that reads no archive does not import it

    try:
        archive = zipfile.ZipFile(handle)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError):
        handle.seek(0)
        return
    with archive:
        members = archive.infolist()
        total = sum(m.file_size for m in members)
        if total > limit:
            raise InputFileError(what, f"its members would inflate to {_size(total)}, more "
                                 f"than the {_size(limit)} read from one input file")
        for m in members:
            if m.filename.endswith(".npy"):
                _check_npy(archive, m, what)
    handle.seek(0)


def _check_npy(archive: zipfile.ZipFile, member: zipfile.ZipInfo, what: str) -> None:
    """Refuse a ``.npy`` member whose header's shape needs more bytes than it holds."""
    import numpy as np

    try:
        with archive.open(member) as stream:
            version = np.lib.format.read_magic(stream)
            read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                           else np.lib.format.read_array_header_2_0)
            shape, _, dtype = read_header(stream)
    except Exception:  # noqa: BLE001 - a damaged member: the reader says so
        return
    count = 1
    for n in shape:
        count *= int(n)
    need = count * (dtype.itemsize or 1)
    if not dtype.hasobject and need > member.file_size:
        raise InputFileError(what, f"member {member.filename!r} declares an array of shape "
                             f"{tuple(shape)} ({_size(need)}) in {_size(member.file_size)}: "
                             "a damaged or forged archive")


@contextlib.contextmanager
def open_archive(path: PathLike, limit: int | None = None,
                 what: str = "") -> Iterator[IO[bytes]]:
    """``path`` opened (:func:`open_regular`), its size and, for a zip archive, its
    members' declared sizes (:func:`check_zip`) checked against ``limit`` (default
    :func:`read_limit`) before the caller reads it."""
    limit = read_limit() if limit is None else limit
    text = os.fspath(path)
    label = f"{what} {text}" if what else text
    with open_regular(path, what) as handle:
        size = os.fstat(handle.fileno()).st_size
        if size > limit:
            raise _too_large(label, size, limit)
        check_zip(handle, limit, label)
        yield handle
