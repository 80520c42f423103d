"""The members of Storm's uncompressed UMB archive, read from its tar headers directly.

Storm writes a model's UMB export as a plain POSIX (ustar) tar file: a 512-byte header
per member (its name, its size in octal, its type, a checksum), the member's bytes
padded to whole blocks after it, two zero blocks at the end.  The PRISM load
(:mod:`mitld_lp.worlds.prism_tables`) reads only where each member's bytes start and how
many there are, to read them with :func:`numpy.fromfile`; :func:`members` gives that
from the headers alone, one ``pread`` a header, where :mod:`tarfile` decodes every field
of every header in Python (about 10 ms of CPU a load, for an archive of some 60 members)
and is itself an import the load would not need otherwise.

Every header is checked (its checksum as the tar format defines it, the ``ustar`` magic,
a size in octal digits).  A member whose name is too long for the header (a state label
named by the expression of the states where the task is decided, ``annotations/aps/
0x280x28t_0x3e...``) comes after a pax extended header (type ``x``) whose ``path``
record names it: that record is read (each record ``"<length> <key>=<value>\n"``, its
length checked), and a ``size`` record overrides the header's size as POSIX says.  An
archive with anything else (another pax key, a global pax header, a GNU long name, a
size in base-256, another format) is read by :mod:`tarfile` instead, so the answer is
:mod:`tarfile`'s on every archive.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

__all__ = ["Member", "members", "read_member"]

BLOCK = 512
"""A tar block: a header is one, a member's bytes are padded to whole ones."""


@dataclass(frozen=True, slots=True)
class Member:
    """A member of the archive: its size in bytes and where they start in the file
    (:class:`tarfile.TarInfo`'s ``size`` and ``offset_data``), and whether it is a
    regular file (a folder has no bytes)."""

    name: str
    size: int
    offset_data: int
    regular: bool = True


class _Other(Exception):
    """A header this reader does not take: :mod:`tarfile` reads the archive."""


def _octal(field: bytes) -> int:
    digits = field.replace(b"\0", b" ").strip()
    if not digits or any(c not in b"01234567" for c in digits):
        raise _Other  # empty, or base-256 (a first byte with its high bit set)
    return int(digits, 8)


PAX_KEYS = frozenset({"path", "size", "mtime", "atime", "ctime", "uid", "gid", "uname",
                      "gname"})
"""The pax records read (``path``, ``size``) or that change nothing read here (times,
owners); any other key sends the archive to :mod:`tarfile`."""


def _header(block: bytes) -> tuple[str, int, bool]:
    """``(name, size, regular)`` of one ustar header block (a pax extended header's
    ``regular`` is None)."""
    if block[257:262] != b"ustar":
        raise _Other
    stored = _octal(block[148:156])
    if stored != sum(block[:148]) + 8 * 32 + sum(block[156:]):  # the field read as spaces
        raise _Other
    kind = block[156:157]
    if kind == b"x":  # a pax extended header: its records are the next member's
        return "", _octal(block[124:136]), None  # type: ignore[return-value]
    if kind not in (b"0", b"\0", b"5"):  # a file or a folder; global pax, GNU names: others
        raise _Other
    name = block[:100].split(b"\0", 1)[0]
    prefix = block[345:500].split(b"\0", 1)[0]
    if prefix:
        name = prefix + b"/" + name
    text = name.decode("utf-8").rstrip("/") if kind == b"5" else name.decode("utf-8")
    return text, _octal(block[124:136]), kind != b"5"


def members(path: str) -> dict[str, Member]:
    """The members of the tar file at ``path`` by name (the last of a name, as
    :mod:`tarfile` keeps it), each with its size and data offset."""
    try:
        return _read(path)
    except (_Other, UnicodeDecodeError):
        import tarfile

        with tarfile.open(path) as tar:
            return {t.name: Member(t.name, t.size, t.offset_data, t.isreg())
                    for t in tar.getmembers()}


def _pax(records: bytes) -> dict[str, str]:
    """The records of a pax extended header, ``"<length> <key>=<value>\n"`` each (the
    length counts the whole record), by key; :class:`_Other` for a key not in
    :data:`PAX_KEYS` or a record that is not of that form."""
    out: dict[str, str] = {}
    at = 0
    while at < len(records):
        if not any(records[at:]):  # padding after the last record
            break
        space = records.find(b" ", at)
        if space < 0 or not records[at:space].isdigit():
            raise _Other
        end = at + int(records[at:space])
        record = records[space + 1 : end]
        if end > len(records) or not record.endswith(b"\n") or b"=" not in record:
            raise _Other
        key, value = record[:-1].split(b"=", 1)
        name = key.decode("utf-8")
        if name not in PAX_KEYS:
            raise _Other
        out[name] = value.decode("utf-8")
        at = end
    return out


def _read(path: str) -> dict[str, Member]:
    out: dict[str, Member] = {}
    fd = os.open(path, os.O_RDONLY)
    try:
        end = os.fstat(fd).st_size
        at = 0
        extended: dict[str, str] = {}  # the last pax header's records, for this member
        while at + BLOCK <= end:
            block = os.pread(fd, BLOCK, at)
            if len(block) < BLOCK:
                raise _Other
            if not any(block):  # the end-of-archive blocks
                if extended:
                    raise _Other  # a pax header with no member after it
                return out
            name, size, regular = _header(block)
            data = at + BLOCK
            if regular is None:  # a pax header: its records name the next member
                if extended or data + size > end:
                    raise _Other
                extended = _pax(os.pread(fd, size, data))
                at = data + -(-size // BLOCK) * BLOCK
                continue
            if "path" in extended:
                name = extended["path"].rstrip("/") if not regular else extended["path"]
            if "size" in extended:
                if not extended["size"].isdigit():
                    raise _Other
                size = int(extended["size"])
            extended = {}
            size_kept = size if regular else 0
            if data + size_kept > end:
                raise _Other  # a member past the end: tarfile says what is wrong
            out[name] = Member(name, size_kept, data, regular)
            at = data + -(-size_kept // BLOCK) * BLOCK
        raise _Other  # no end-of-archive block: tarfile says what is wrong
    finally:
        os.close(fd)


def read_member(path: str, member: Member) -> bytes:
    """The bytes of ``member`` of the archive at ``path``."""
    with open(path, "rb") as fh:
        fh.seek(member.offset_data)
        return fh.read(member.size)
