"""The results file of a sweep: one row per point, CSV or Parquet.

Columns: ``sweep`` and ``sweep_id`` (which sweep the row belongs to), then one column per
parameter (named by its key path), then :data:`mitld_lp.sweep.rows.RESULT_COLUMNS`.

* **CSV** (``.csv``): a header, then one line per point, appended and flushed as each
  point finishes; a parameter's cell is its value as JSON (``0.1``, ``[2.0, 4.0]``,
  ``"text"``), an absent number is empty, booleans are ``True``/``False``.  A last line
  cut short by a kill is dropped when the file is read again.
* **Parquet** (``.parquet``, needs pyarrow): rewritten whole (by the package's one
  writer, :func:`mitld_lp.files.write.replacing_path`: a temporary file renamed over the old
  one) at most once a second and at the end; numeric parameters
  are numeric columns, others JSON text.

A results file is only ever extended by the sweep it belongs to: opening it for another
sweep (another ``sweep_id``), or opening a file that is no results file, is refused.
It is read only if it is a regular file (not a FIFO or a device), and only up to
:func:`mitld_lp.files.write.read_limit`; a path the writing rule refuses (a folder, a folder
under ``/proc``) is refused before any point.

**One writer at a time**: :class:`Results` holds an advisory lock (``flock``) on the
file ``.NAME.lock`` beside the results file ``NAME`` from before it reads the file until
:meth:`Results.close`.  ``NAME`` and its folder are the file's own, symlinks resolved, so
that every name reaching the file (a symlink, ``../x.csv``, an absolute path) takes the
same lock; a file with another name of its own (a hard link) is not extended, since a
sweep through that name would take another lock.  A second sweep that opens the same
results file meanwhile (in this process or another) is refused at once with one line
naming the process that holds it, and writes nothing: two writers never duplicate or
interleave rows.  The lock file is removed when the lock is released; one left by a
killed sweep holds no lock.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import IO, Any

from mitld_lp.files import write as files
from mitld_lp.sweep.rows import META_COLUMNS, RESULT_COLUMNS
from mitld_lp.sweep.spec import SweepError

__all__ = ["Results", "read_results", "point_key", "SUFFIXES"]

SUFFIXES = (".csv", ".parquet")
_REWRITE_EVERY = 1.0  # seconds between two rewrites of a Parquet file


def _norm(value: Any) -> Any:
    if isinstance(value, bool) or value is None:
        return value
    if isinstance(value, int | float):
        return float(value)
    if isinstance(value, list | tuple):
        return [_norm(v) for v in value]
    if isinstance(value, dict):
        return {k: _norm(v) for k, v in value.items()}
    return value


def point_key(values: Iterable[Any]) -> str:
    """The identity of a point: its values as JSON, numbers as floats (``3`` and
    ``3.0`` are one point, whatever a file made of them)."""
    return json.dumps([_norm(v) for v in values], sort_keys=True, default=str)


# --------------------------------------------------------------------------- cells


def _result_cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _read_result(kind: type, text: str) -> Any:
    if text == "":
        return None
    if kind is bool:
        if text not in ("True", "False"):
            raise ValueError(f"not a boolean: {text!r}")
        return text == "True"
    return kind(text)


def _read_parameter(value: Any) -> Any:
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def _check_suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise SweepError(f"{path}: a results file ends in {' or '.join(SUFFIXES)}")
    if suffix == ".parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise SweepError(f"{path}: Parquet needs pyarrow (pip install 'mitld_lp[sweep]'), "
                             "or write .csv") from None
    return suffix


# --------------------------------------------------------------------------- reading


def read_results(path: str | os.PathLike[str]) -> tuple[list[str], list[dict[str, Any]], int]:
    """``(columns, rows, dropped)`` of a results file: typed rows (parameters decoded
    from JSON, the result columns as :data:`RESULT_COLUMNS` says) and the number of
    lines that could not be read (a line cut short)."""
    p = Path(path)
    suffix = _check_suffix(p)
    try:
        data = files.read_bytes(p, files.read_limit(share=16 if suffix == ".parquet" else 64))
        if suffix == ".parquet":
            import pyarrow.parquet as pq

            table = pq.read_table(io.BytesIO(data))
            columns, raw = list(table.column_names), table.to_pylist()
            rows = [{c: (r[c] if c in RESULT_COLUMNS or c in META_COLUMNS
                         else _read_parameter(r[c])) for c in columns} for r in raw]
            return columns, rows, 0
        lines = list(csv.reader(io.StringIO(data.decode("utf-8"), newline="")))
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as exc:
        message = getattr(exc, "strerror", None) or str(exc).splitlines()[0]
        raise SweepError(f"{p}: cannot read as a results file: {message}") from exc
    if not lines:
        return [], [], 0
    columns, out, dropped = lines[0], [], 0
    for line in lines[1:]:
        if len(line) != len(columns):
            dropped += 1
            continue
        try:
            out.append({c: (_read_result(RESULT_COLUMNS[c], v) if c in RESULT_COLUMNS
                            else v if c in META_COLUMNS else _read_parameter(v))
                        for c, v in zip(columns, line, strict=True)})
        except ValueError:
            dropped += 1
    return columns, out, dropped


# --------------------------------------------------------------------------- writing


class Results:
    """The results file of one sweep, open for appending rows.

    ``Results(path, name, sweep_id, parameters, force=...)`` reads the rows already
    there (``rows``) after checking that they are this sweep's; ``force`` starts the
    file anew instead.  ``add(row)`` records a row; ``close()`` writes what is pending.
    """

    def __init__(self, path: str | os.PathLike[str], name: str, sweep_id: str,
                 parameters: Sequence[str], *, force: bool = False) -> None:
        self.path = Path(path)
        self.suffix = _check_suffix(self.path)
        self.columns = [*META_COLUMNS, *parameters, *RESULT_COLUMNS]
        self.parameters = tuple(parameters)
        self.meta = {"sweep": name, "sweep_id": sweep_id}
        self.rows: list[dict[str, Any]] = []
        self._written = 0.0
        try:
            files.writable_path(self.path, overwrite=True, what="results file")
        except files.OutputPathError as exc:
            raise SweepError(str(exc)) from None
        self._lock: _Lock | None = _Lock(self.path)
        try:
            if self.path.exists() and not force:
                self._adopt(name, sweep_id)
            else:
                if self.path.exists():
                    _regular(self.path)
                self.rewrite([])
        except BaseException:
            self.release()
            raise

    def _adopt(self, name: str, sweep_id: str) -> None:
        _one_name(self.path)
        columns, rows, dropped = read_results(self.path)
        if not columns and not rows:  # an empty file
            self.rewrite([])
            return
        refuse = f"{self.path}: exists and "
        fix = "; choose another results file, or pass --force to replace it"
        if "sweep_id" not in columns:
            raise SweepError(refuse + f"is not the results file of a sweep{fix}")
        others = sorted({(r["sweep"], r["sweep_id"]) for r in rows} - {(name, sweep_id)})
        if others:
            raise SweepError(refuse + f"holds results of sweep {others[0][0]!r} "
                             f"(id {others[0][1]}), not of this sweep {name!r} (id "
                             f"{sweep_id}: its base model, [set], parameters or solve "
                             f"settings differ){fix}")
        if columns != self.columns:
            raise SweepError(refuse + f"has the columns {', '.join(columns)}, not those of "
                             f"this sweep{fix}")
        self.rows = rows
        if dropped:
            self.rewrite(rows)

    def rewrite(self, rows: list[dict[str, Any]]) -> None:
        """Replace the file's content by ``rows`` (atomically)."""
        self.rows = list(rows)
        if self.suffix == ".parquet":
            with files.replacing_path(self.path) as scratch:
                self._write_parquet(scratch)
        else:
            with files.replacing(self.path, newline="") as handle:
                self._write_csv(handle, self.rows, header=True)
        self._written = time.monotonic()

    def _write_csv(self, handle: IO[str], rows: Iterable[dict[str, Any]],
                   header: bool) -> None:
        writer = csv.writer(handle, lineterminator="\n")
        if header:
            writer.writerow(self.columns)
        for row in rows:
            writer.writerow(
                [_result_cell(row[c]) if c in RESULT_COLUMNS or c in META_COLUMNS
                 else json.dumps(row[c], ensure_ascii=False) for c in self.columns])
        handle.flush()

    def _write_parquet(self, path: Path) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        types = {str: pa.string(), bool: pa.bool_(), float: pa.float64(), int: pa.int64()}
        arrays, fields = [], []
        for c in self.columns:
            values = [r[c] for r in self.rows]
            if c in META_COLUMNS:
                kind = pa.string()
            elif c in RESULT_COLUMNS:
                kind = types[RESULT_COLUMNS[c]]
            else:
                kind, values = _parameter_column(values)
            arrays.append(pa.array(values, type=kind))
            fields.append(pa.field(c, kind))
        pq.write_table(pa.Table.from_arrays(arrays, schema=pa.schema(fields)), path)

    def add(self, row: dict[str, Any]) -> None:
        """Record one row (the meta columns are filled in here)."""
        row = {**self.meta, **row}
        self.rows.append(row)
        if self.suffix == ".csv":  # appended and flushed: a row survives a kill
            with self.path.open("a", newline="", encoding="utf-8") as handle:
                self._write_csv(handle, [row], header=False)
        elif time.monotonic() - self._written >= _REWRITE_EVERY:
            self.rewrite(self.rows)

    def close(self) -> None:
        """Write what is pending, then release the lock."""
        try:
            if self.suffix == ".parquet" and self._lock is not None:
                self.rewrite(self.rows)
        finally:
            self.release()

    def __del__(self) -> None:  # an error before close(): the lock goes with the object
        with contextlib.suppress(Exception):
            self.release()

    def release(self) -> None:
        """Release the lock on the results file (once; :meth:`close` does it)."""
        lock, self._lock = self._lock, None
        if lock is not None:
            lock.release()


def _regular(path: Path) -> None:
    """Refuse an existing results path that is no regular file (a device, a FIFO)."""
    try:
        files.open_regular(path, "results file").close()
    except OSError as exc:
        raise SweepError(str(exc) if isinstance(exc, files.InputFileError)
                         else f"{path}: cannot read: {exc.strerror or exc}") from None


def _one_name(path: Path) -> None:
    """Refuse to extend a results file that has another name of its own (a hard link):
    a sweep given that name would lock ``.OTHER.lock`` and append to the same rows."""
    try:
        links = os.stat(path).st_nlink
    except OSError:
        return  # read_results says why it cannot be read
    if links > 1:
        raise SweepError(f"{path}: has {links} names (hard links), so another sweep could "
                         "write it under another name; give a file of its own (a copy), "
                         "or pass --force to start it anew")


class _Lock:
    """An exclusive advisory lock on ``.NAME.lock`` beside the results file ``NAME``,
    symlinks resolved (module docstring), taken without waiting: :class:`SweepError` if
    another writer holds it."""

    def __init__(self, results: Path) -> None:
        import fcntl

        real = Path(os.path.realpath(results))  # the file itself, whatever name reached it
        self.path = real.with_name(f".{real.name}.lock")
        for _ in range(100):  # the holder may remove the file between open and flock
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            except OSError as exc:
                raise SweepError(f"{results}: cannot lock it ({self.path}: "
                                 f"{exc.strerror or exc})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 64, 0).decode("ascii", "replace").strip()
                os.close(fd)
                raise SweepError(
                    f"{results}: another sweep is writing it (process {holder or '?'} holds "
                    f"{self.path.name}); wait for it to end, or choose another results "
                    "file") from None
            except OSError as exc:
                os.close(fd)
                raise SweepError(f"{results}: cannot lock it ({self.path}: "
                                 f"{exc.strerror or exc})") from None
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(self.path))
            except FileNotFoundError:
                same = False
            if same:
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                self.fd: int | None = fd
                return
            os.close(fd)  # removed by its last holder meanwhile: lock the new one
        raise SweepError(f"{results}: cannot lock it ({self.path} keeps changing)")

    def release(self) -> None:
        fd, self.fd = self.fd, None
        if fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)  # while still held: a waiting opener then retries
        os.close(fd)


def _parameter_column(values: list[Any]) -> tuple[Any, list[Any]]:
    import pyarrow as pa

    numbers = [v for v in values if not isinstance(v, bool) and isinstance(v, int | float)]
    if len(numbers) == len(values):
        if all(isinstance(v, int) for v in values):
            return pa.int64(), values
        return pa.float64(), [float(v) for v in values]
    return pa.string(), [json.dumps(v, ensure_ascii=False) for v in values]
