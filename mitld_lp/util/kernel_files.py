"""The kernel loader's cache files (:mod:`mitld_lp.util.kernel_loader`): where they
go (numba's cache directories for a function, in its locators' order), their layout
(:func:`pack`), the undefined symbols of an object file, and a file written whole (a
temporary file renamed over the old one).  NumPy-free, numba-free: only the standard
library."""

from __future__ import annotations

import hashlib
import marshal
import os
import struct
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["FORMAT", "MAGIC", "SUFFIX", "directories", "file_name", "forget_listing", "listing",
           "pack", "undefined_symbols", "unpack", "write"]

FORMAT = "mitld_lp kernel object 1"
MAGIC = (FORMAT + "\n").encode()
_HEADER = struct.Struct("<QQ")  # lengths of the metadata and of the object code
SUFFIX = ".kobj"


def _subpath(py_file: str) -> str:
    """numba's ``get_suitable_cache_subpath``."""
    sub = os.path.dirname(os.path.abspath(py_file))
    return "_".join([os.path.split(sub)[-1], hashlib.sha1(sub.encode()).hexdigest()])


_directories: dict[tuple, list[Path]] = {}  # (file, the settings they follow) -> folders


def directories(py_file: str) -> list[Path]:
    """numba's cache directories for a function of ``py_file``, in its locators' order
    (remembered for the file and the settings they follow: the environment variables,
    the working directory where a path is relative)."""
    env = os.environ.get("NUMBA_CACHE_DIR")
    relative = not os.path.isabs(py_file) or bool(env) and not os.path.isabs(env)
    key = (py_file, env, os.environ.get("XDG_CACHE_HOME"), os.environ.get("HOME"),
           os.getcwd() if relative else None)
    found = _directories.get(key)
    if found is None:
        found = _directories[key] = _find_directories(py_file, env)
    return list(found)


def _find_directories(py_file: str, env: str | None) -> list[Path]:
    if env:
        return [Path(os.path.abspath(env)) / _subpath(py_file)]
    home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                             ".cache")
    return [Path(os.path.dirname(py_file)) / "__pycache__",
            Path(home) / "numba" / _subpath(py_file)]


def file_name(py_file: str, qualname: str, key: tuple) -> str:
    """A kernel's cache file name for the argument types ``key``."""
    stem = os.path.splitext(os.path.basename(py_file))[0]
    digest = hashlib.sha256(repr(key).encode()).hexdigest()[:20]
    return f"{stem}.{qualname}-{digest}{SUFFIX}"


_listings: dict[str, tuple[int, dict[str, list[str]]]] = {}  # folder -> (mtime, stems)


def listing(directory: Path) -> dict[str, list[str]]:
    """The cache files of a folder by their kernel's stem (the name up to its last
    ``-``, :func:`file_name`), listed once and again when the folder's modification time
    has moved (a file written, renamed in or removed there, by any process) or after
    :func:`write` wrote one there (:func:`forget_listing`: a clock too coarse to move
    within the listing's tick); {} where there is no such folder."""
    where = str(directory)
    try:
        stamp = os.stat(where).st_mtime_ns
        found = _listings.get(where)
        if found is not None and found[0] == stamp:
            return found[1]
        names = os.listdir(where)
    except OSError:
        _listings.pop(where, None)
        return {}
    stems: dict[str, list[str]] = {}
    for name in names:
        if name.endswith(SUFFIX) and "-" in name:
            stems.setdefault(name.rsplit("-", 1)[0], []).append(name)
    _listings[where] = (stamp, stems)
    return stems


def forget_listing(directory: Path) -> None:
    """Drop the listing of ``directory`` (:func:`listing`): it is made afresh next."""
    _listings.pop(str(directory), None)


def pack(meta: bytes, object_code: bytes) -> bytes:
    """A cache file: MAGIC, the two lengths, the SHA-256 of what follows, the metadata
    (marshal: the key, the wrapper's and environments' names, the constants' dtypes, the
    undefined symbols) and the object code."""
    payload = meta + object_code
    return MAGIC + _HEADER.pack(len(meta), len(object_code)) + \
        hashlib.sha256(payload).digest() + payload


def unpack(data: bytes) -> tuple[dict[str, Any], bytes] | None:
    start = len(MAGIC) + _HEADER.size + 32
    if len(data) < start or not data.startswith(MAGIC):
        return None
    nm, no = _HEADER.unpack_from(data, len(MAGIC))
    payload = data[start:]
    if len(payload) != nm + no or hashlib.sha256(payload).digest() != data[start - 32:start]:
        return None
    try:
        meta = marshal.loads(payload[:nm])
    except (EOFError, ValueError, TypeError):
        return None
    if not isinstance(meta, dict):
        return None
    return meta, payload[nm:]


def undefined_symbols(obj: bytes) -> set[str] | None:
    """The undefined symbols of an ELF64 little-endian relocatable object (numba's object
    code on Linux), or None for another format."""
    if obj[:4] != b"\x7fELF" or obj[4] != 2 or obj[5] != 1:
        return None
    shoff = struct.unpack_from("<Q", obj, 0x28)[0]
    shentsize, shnum = struct.unpack_from("<HH", obj, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + i * shentsize)
                for i in range(shnum)]
    names: set[str] = set()
    for sec in sections:
        if sec[1] != 2:  # SHT_SYMTAB
            continue
        strtab = sections[sec[6]]
        for off in range(sec[4] + 24, sec[4] + sec[5], 24):  # entry 0 is null
            st_name, _info, _other, shndx = struct.unpack_from("<IBBH", obj, off)
            if shndx == 0 and st_name:
                start = strtab[4] + st_name
                names.add(obj[start:obj.index(b"\0", start)].decode())
    return names


def write(path: Path, data: bytes) -> None:
    """``data`` into ``path`` by a temporary file renamed over it; nothing where the
    directory cannot be written."""
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
        forget_listing(path.parent)
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
