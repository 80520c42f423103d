"""Every file the package writes goes through here: one rule for where a file may be
written, and one way of writing it.

The rule (:func:`writable_path`), checked before any work: the path is not empty and
not a folder, its folder exists, its suffix is one the format allows, and it names no
existing file -- a dangling symlink counts as existing -- unless the caller allows
overwriting (``overwrite=True``, the command line's ``--force``).  Two outputs of one
command must not name the same file (:func:`distinct_outputs`).

The writing (:func:`replacing` for a stream, :func:`replacing_path` for a writer that
takes a file name -- a figure, a Parquet table, HiGHS's LP file -- and the helpers
:func:`write_text`, :func:`write_figure`, :func:`write_policy` over them): the content
goes to a temporary file beside the target, which is renamed over the target only once
it is complete. A write that fails or is interrupted (Ctrl-C) leaves the target exactly
as it was and removes the temporary file; a command that stops a writing thread from
outside (the command line on Ctrl-C or a time limit) calls :func:`abandon` with that
thread. With ``overwrite`` a symlink is written through (its target is replaced, the
link kept), and a target that is not a regular file (a device such as ``/dev/null``) is
written directly: there is nothing to rename over. A path under ``/proc`` or ``/sys``
(the kernel's own tables, which take no new file) is refused by the rule.

The readers of the files a user names (:func:`read_bytes`, :func:`read_text`,
:func:`open_archive`, :func:`check_zip`: regular files only, bounded, sizes checked
before reading or inflating) live in :mod:`mitld_lp.files.rules`, which imports nothing
of the package so that every reader may use it, and are re-exported here.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import secrets
import shutil
import stat
import threading
import time
import weakref
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import IO, Any, Literal

from mitld_lp.files.rules import (
    InputFileError,
    OutputPathError,
    check_zip,
    irregular_kind,
    kernel_folder,
    open_archive,
    open_regular,
    read_bytes,
    read_limit,
    read_text,
)

#: A result of :func:`mitld_lp.synthesis.synthesize` (not imported: this module is below
#: every stage; :func:`write_policy` asks the result for its table).
SynthesisResult = Any

__all__ = [
    "OutputPathError",
    "WriteAbandoned",
    "writable_path",
    "distinct_outputs",
    "replacing",
    "replacing_path",
    "write_text",
    "write_figure",
    "write_policy",
    "POLICY_SUFFIXES",
    "POLICY_COLUMNS",
    "abandon",
    "abandoned",
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


class WriteAbandoned(Exception):
    """The writing thread was abandoned (:func:`abandon`): nothing was renamed into
    place and the temporary file is gone."""


# --------------------------------------------------------------------------- the rule


def writable_path(
    path: PathLike,
    *,
    overwrite: bool = False,
    suffixes: Iterable[str] = (),
    what: str = "",
    force: str = "overwrite=True",
) -> Path:
    """``path`` as a :class:`~pathlib.Path` if a file may be written there (module docs).

    ``suffixes``: the allowed suffixes, lower case with the dot (any case is accepted in
    the path); none: any.  ``what`` names the path in messages (``--drn``); ``force``
    is how the caller allows overwriting, quoted in the message.

    Raises:
        OutputPathError: empty path, wrong suffix, a folder, or no such folder.
        FileExistsError: the path exists (or is a dangling symlink) and not ``overwrite``.
    """
    text = os.fspath(path)
    label = f"{what} {text}" if what else text
    if text == "":
        raise OutputPathError(f"{what or 'output path'}: the path is empty")
    out = Path(text)
    allowed = tuple(suffixes)
    if allowed and out.suffix.lower() not in allowed:
        raise OutputPathError(f"{label}: the suffix must be one of {', '.join(allowed)}")
    if out.is_dir():
        raise OutputPathError(f"{label}: is a directory")
    folder = out.parent
    if not folder.is_dir():
        raise OutputPathError(f"{label}: the folder {folder} does not exist")
    kernel = kernel_folder(folder)
    if kernel is not None:
        raise OutputPathError(f"{label}: is under {kernel}, the kernel's own tables, where "
                              "no file can be written")
    if os.path.lexists(out) and not overwrite:
        dangling = out.is_symlink() and not out.exists()
        raise FileExistsError(
            f"{text}: exists{' (a dangling symlink)' if dangling else ''}; "
            f"pass {force} to replace it")
    return out


def distinct_outputs(named: Iterable[tuple[str, Path]]) -> None:
    """Refuse two outputs that are one file: ``named`` pairs a name (``--lp``) with a
    path already checked by :func:`writable_path`.  Raises :class:`OutputPathError`.

    One file whatever names reach it: an existing file is known by its device and inode
    (a symlink, ``..``, a hard link, a second mount of its folder), a new one by its
    folder's device and inode and its name."""
    seen: dict[tuple[int, int, str], str] = {}
    for what, path in named:
        key = _identity(path)
        if key in seen:
            raise OutputPathError(f"{seen[key]} and {what} name the same file {path}")
        seen[key] = what


def _identity(path: Path) -> tuple[int, int, str]:
    """The file ``path`` names (:func:`distinct_outputs`)."""
    real = Path(os.path.realpath(path))
    with contextlib.suppress(OSError):
        own = os.stat(real)
        return own.st_dev, own.st_ino, ""
    try:
        folder = os.stat(real.parent)
    except OSError:
        return 0, 0, str(real)
    return folder.st_dev, folder.st_ino, real.name


# --------------------------------------------------------------------------- the writing

_lock = threading.Lock()
_scratch: dict[Path, threading.Thread] = {}
"""Temporary files and folders being written, and the thread writing each."""
_abandoned: weakref.WeakSet[threading.Thread] = weakref.WeakSet()


def abandon(thread: threading.Thread) -> None:
    """Stop ``thread``'s writes: remove its temporary files now, and make it raise
    :class:`WriteAbandoned` instead of renaming or starting another write.  Called by
    the thread that interrupts ``thread`` (which may be stuck in a native call)."""
    with _lock:
        _abandoned.add(thread)
        mine = [p for p, owner in _scratch.items() if owner is thread]
        for p in mine:
            _remove(p)
            del _scratch[p]


def abandoned(thread: threading.Thread | None = None, timeout: float = 0.0) -> bool:
    """Whether ``thread`` (default: this one) was abandoned (:func:`abandon`), waiting up
    to ``timeout`` seconds for it to be."""
    me = threading.current_thread() if thread is None else thread
    end = time.monotonic() + timeout
    while True:
        with _lock:
            if me in _abandoned:
                return True
        left = end - time.monotonic()
        if left <= 0:
            return False
        time.sleep(min(left, 0.02))


def _remove(scratch: Path) -> None:
    if scratch.is_dir() and not scratch.is_symlink():
        shutil.rmtree(scratch, ignore_errors=True)
    else:
        with contextlib.suppress(FileNotFoundError):
            scratch.unlink()


def _destination(path: Path) -> Path:
    """Where the bytes go: the final file a symlink points to (checked by the rule)."""
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def _is_stream(path: Path) -> bool:
    """An existing target that is no regular file (a device, a FIFO): write in place."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return False
    return not stat.S_ISREG(mode)


def _new_scratch(final: Path, folder: bool) -> Path:
    """A new temporary file (or folder) beside ``final``, registered to this thread."""
    me = threading.current_thread()
    with _lock:
        _check_live(final)
        while True:
            scratch = final.with_name(f".{final.name}.{secrets.token_hex(4)}.part")
            try:
                if folder:
                    scratch.mkdir()
                else:
                    os.close(os.open(scratch, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666))
            except FileExistsError:
                continue
            _scratch[scratch] = me
            from mitld_lp.util import watch  # imported by the first scratch file

            watch.report(str(scratch))  # a watching parent removes it if it kills us
            return scratch


def _check_live(final: Path) -> None:
    """Raise :class:`WriteAbandoned` if this thread's writes were abandoned."""
    if threading.current_thread() in _abandoned:
        raise WriteAbandoned(f"{final}: not written (interrupted)")


def _commit(written: Path, final: Path) -> None:
    """Rename the complete file ``written`` over ``final`` (keeping the mode of the
    file it replaces), unless this thread was abandoned meanwhile."""
    try:
        with contextlib.suppress(FileNotFoundError):
            os.chmod(written, stat.S_IMODE(final.stat().st_mode))
        fd = os.open(written, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except FileNotFoundError:  # removed by abandon() while it was written
        _check_live(final)
        raise
    with _lock:
        _check_live(final)
        os.replace(written, final)


@contextlib.contextmanager
def replacing_path(path: Path) -> Iterator[Path]:
    """A temporary file name beside ``path`` with the same name (so the same suffix),
    for writers that take a file name (HiGHS); renamed over ``path`` when the block ends
    without an exception.  ``path`` has passed :func:`writable_path`."""
    final = _destination(path)
    if _is_stream(final):
        yield final
        return
    scratch = _new_scratch(final, folder=True)
    inside = scratch / final.name
    try:
        yield inside
        _check_live(final)
        if not inside.is_file():
            raise OSError(f"{path}: the writer produced no file")
        _commit(inside, final)
    finally:
        with _lock:
            _scratch.pop(scratch, None)
        _remove(scratch)


@contextlib.contextmanager
def replacing(
    path: Path,
    mode: Literal["w", "wb"] = "w",
    *,
    encoding: str = "utf-8",
    newline: str | None = None,
) -> Iterator[IO]:
    """An open temporary file beside ``path``, renamed over it when the block ends
    without an exception (module docs).  ``path`` has passed :func:`writable_path`.
    ``encoding`` and ``newline`` apply to text mode ``"w"``."""
    final = _destination(path)
    if _is_stream(final):
        with _open(final, mode, encoding, newline) as handle:
            yield handle
        return
    scratch = _new_scratch(final, folder=False)
    try:
        with _open(scratch, mode, encoding, newline) as handle:
            yield handle
        _commit(scratch, final)
    finally:
        with _lock:
            _scratch.pop(scratch, None)
        with contextlib.suppress(FileNotFoundError):
            scratch.unlink()


def _open(path: Path, mode: str, encoding: str, newline: str | None) -> IO:
    if "b" in mode:
        return path.open("wb")
    return path.open("w", encoding=encoding, newline=newline)


def write_text(
    path: PathLike,
    text: str,
    *,
    overwrite: bool = False,
    suffixes: Iterable[str] = (),
) -> Path:
    """Write ``text`` (UTF-8) to ``path`` under the rule, replacing the file in one step."""
    out = writable_path(path, overwrite=overwrite, suffixes=suffixes)
    with replacing(out) as handle:
        handle.write(text)
    return out


def write_figure(
    figure: Any,
    path: PathLike,
    *,
    overwrite: bool = False,
    suffixes: Iterable[str] = (),
    dpi: int = 100,
) -> Path:
    """Write a Matplotlib ``figure`` (its format from the suffix of ``path``) under the
    rule, replacing the file in one step (:func:`replacing_path`)."""
    out = writable_path(path, overwrite=overwrite, suffixes=suffixes)
    with replacing_path(out) as scratch:
        figure.savefig(scratch, dpi=dpi)
    return out


POLICY_SUFFIXES = (".csv", ".json")

POLICY_COLUMNS = ("game_state", "automaton_state", "pending", "clock", "action", "value",
                  "accepting_component")
"""The keys of a policy table's row (:func:`mitld_lp.report.policy_table`), in the order
the CSV file writes them."""


def write_policy(
    result: SynthesisResult, path: PathLike, *, overwrite: bool = False
) -> Path:
    """Write ``result``'s policy table (:func:`mitld_lp.report.policy_table`) to
    ``path``: ``.csv`` (one row per state, the columns of
    :data:`POLICY_COLUMNS`, pending events joined by spaces, values
    with every digit) or ``.json`` (a list of objects), under the rule."""
    out = writable_path(path, overwrite=overwrite, suffixes=POLICY_SUFFIXES)
    rows = result.policy_table()  # mitld_lp.report.policy_table, every route's
    if out.suffix.lower() == ".json":
        with replacing(out) as handle:
            handle.write(json.dumps(rows, default=str) + "\n")
        return out
    with replacing(out, newline="") as handle:
        writer: csv.DictWriter[str] = csv.DictWriter(handle, fieldnames=list(POLICY_COLUMNS))
        writer.writeheader()
        for row in rows:
            writer.writerow({**row, "game_state": str(row["game_state"]),
                             "pending": " ".join(row["pending"]),
                             "value": repr(row["value"])})
    return out
