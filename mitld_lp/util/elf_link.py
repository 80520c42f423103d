"""A small runtime linker for ELF64 x86-64 relocatable objects (numba's cached object
code), so that :mod:`mitld_lp.util.kernel_loader` runs a kernel without importing
llvmlite (whose shared library adds about 40 MB to a process's resident size).

:func:`link` parses the object (section headers, the symbol table, the RELA
relocation sections), lays its allocated sections out in one anonymous mapping (the
executable sections first, then the read-only ones with the GOT entries it lays out,
then the writable ones with the common symbols; each group page-aligned), resolves each
undefined symbol by the caller's function, applies the relocations, and then makes the
executable pages read + execute and the read-only pages read-only.  The relocation
types applied: ``R_X86_64_64``, ``PC64``, ``PC32``, ``PLT32`` (through a stub
``jmp *addr(%rip)`` laid out after the code where the target is beyond 2 GiB), ``32``,
``32S``, ``GOTPCREL``, ``GOTPCRELX``, ``REX_GOTPCRELX`` (through a GOT entry, the
instruction left as it is).  Unwinding tables (``.eh_frame``) are not loaded: numba's
code raises no C++ exceptions.

Anything it does not know (another class, byte order, machine or file type, a section
of thread-local data or of constructors, a ``REL`` section, an indirect function, a
symbol the resolver does not give, a relocation type or a value out of its field's
range, a mapping the system refuses) raises :class:`Refused` before any code is made
executable; the caller then links another way.  Standard library only (``ctypes`` for
``mmap`` and ``mprotect``)."""

from __future__ import annotations

import ctypes
import platform
import struct
import sys
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["KNOWN", "Linked", "Refused", "link", "supported"]

R_X86_64_NONE, R_X86_64_64, R_X86_64_PC32, R_X86_64_PLT32 = 0, 1, 2, 4
R_X86_64_GOTPCREL, R_X86_64_32, R_X86_64_32S, R_X86_64_PC64 = 9, 10, 11, 24
R_X86_64_GOTPCRELX, R_X86_64_REX_GOTPCRELX = 41, 42
_GOT_TYPES = (R_X86_64_GOTPCREL, R_X86_64_GOTPCRELX, R_X86_64_REX_GOTPCRELX)
KNOWN = frozenset((R_X86_64_NONE, R_X86_64_64, R_X86_64_PC32, R_X86_64_PLT32, R_X86_64_32,
                   R_X86_64_32S, R_X86_64_PC64, *_GOT_TYPES))
"""The relocation types :func:`link` applies; any other is refused."""

SHT_PROGBITS, SHT_SYMTAB, SHT_RELA, SHT_NOBITS, SHT_REL = 1, 2, 4, 8, 9
SHT_X86_64_UNWIND = 0x70000001
SHF_WRITE, SHF_ALLOC, SHF_EXECINSTR, SHF_TLS = 0x1, 0x2, 0x4, 0x400
SHN_UNDEF, SHN_ABS, SHN_COMMON, SHN_LORESERVE = 0, 0xFFF1, 0xFFF2, 0xFF00
STB_LOCAL = 0
STT_SECTION, STT_TLS, STT_GNU_IFUNC = 3, 6, 10

_PAGE = 4096
_STUB = 16  # jmp *0(%rip) (6 bytes), the target's address (8), two bytes of padding
_SECTION = struct.Struct("<IIQQQQIIQQ")
_SYMBOL = struct.Struct("<IBBHQQ")
_RELA = struct.Struct("<QQq")
_U64 = struct.Struct("<Q")


class Refused(Exception):
    """The object, or this process, is not one this linker handles (module docs)."""


def supported() -> bool:
    """Whether this process is one the linker is for: Linux on x86-64."""
    return sys.platform.startswith("linux") and platform.machine() in ("x86_64", "AMD64")


@dataclass
class Linked:
    """An object linked in memory: its mapping (never unmapped: code may still run)
    and the address of each named symbol it defines with global or weak binding."""

    base: int
    size: int
    symbols: dict[str, int] = field(default_factory=dict)


@dataclass
class _Section:
    index: int
    name: str
    type: int
    flags: int
    offset: int
    size: int
    link: int
    info: int
    align: int


def _name(obj: bytes, at: int) -> str:
    end = obj.find(b"\0", at)
    if end < 0:
        raise Refused("a name runs past the end of the object")
    return obj[at:end].decode("utf-8", "replace")


def _sections(obj: bytes) -> list[_Section]:
    if len(obj) < 64 or obj[:4] != b"\x7fELF":
        raise Refused("not an ELF object")
    if obj[4] != 2 or obj[5] != 1:
        raise Refused("not ELF64 little-endian")
    e_type, e_machine = struct.unpack_from("<HH", obj, 16)
    if e_type != 1 or e_machine != 62:
        raise Refused(f"not an x86-64 relocatable object (type {e_type}, machine {e_machine})")
    shoff = struct.unpack_from("<Q", obj, 0x28)[0]
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", obj, 0x3A)
    if shentsize != _SECTION.size or shnum == 0 or shstrndx >= shnum:
        raise Refused("unexpected section header table")
    if shoff + shnum * shentsize > len(obj):
        raise Refused("section headers past the end of the object")
    raw = [_SECTION.unpack_from(obj, shoff + i * shentsize) for i in range(shnum)]
    strings = raw[shstrndx][4]
    out = []
    for i, (nm, typ, flags, _addr, off, size, link, info, align, _ent) in enumerate(raw):
        if typ != SHT_NOBITS and off + size > len(obj):
            raise Refused(f"section {i} past the end of the object")
        out.append(_Section(i, _name(obj, strings + nm), typ, flags, off, size, link, info,
                            max(align, 1)))
    return out


def _skipped(sec: _Section) -> bool:
    """An allocated section not loaded: unwinding tables."""
    return sec.type == SHT_X86_64_UNWIND or sec.name == ".eh_frame"


def _loaded_sections(sections: list[_Section]) -> list[_Section]:
    out = []
    for sec in sections:
        if sec.type == SHT_REL:
            raise Refused(f"REL relocations ({sec.name})")
        if not sec.flags & SHF_ALLOC or _skipped(sec):
            continue
        if sec.flags & SHF_TLS or sec.type not in (SHT_PROGBITS, SHT_NOBITS):
            raise Refused(f"section {sec.name!r} of type {sec.type:#x}")
        if sec.name.startswith((".init", ".fini", ".preinit", ".ctors", ".dtors")):
            raise Refused(f"section {sec.name!r} (constructors)")
        out.append(sec)
    return out


def _symbols(obj: bytes, sections: list[_Section]) -> tuple[list[tuple], _Section]:
    """The symbol table's entries as read (``st_name`` an offset, not yet a name: most
    are local and never named) and the table's section."""
    tables = [s for s in sections if s.type == SHT_SYMTAB]
    if len(tables) != 1:
        raise Refused("not one symbol table")
    table = tables[0]
    if table.size % _SYMBOL.size:
        raise Refused("a symbol table of a partial entry")
    return list(_SYMBOL.iter_unpack(obj[table.offset:table.offset + table.size])), table


def _align(n: int, a: int) -> int:
    return (n + a - 1) // a * a


def link(obj: bytes, resolve: Callable[[str], int | None]) -> Linked:
    """Link ``obj`` into this process (module docs); ``resolve(name)`` gives the address
    of an undefined symbol, or None (then :class:`Refused`)."""
    if not supported():
        raise Refused("not x86-64 Linux")
    sections = _sections(obj)
    loaded = _loaded_sections(sections)
    symbols, table = _symbols(obj, sections)
    strings = sections[table.link]
    text = obj[strings.offset:strings.offset + strings.size]
    if text.isascii():  # (numba's names are) read as one str, each name a slice of it
        text = text.decode("ascii")

        def name_of(sym: int) -> str:
            st_name = symbols[sym][0]
            end = text.find("\0", st_name)
            if end < 0:
                raise Refused("a name runs past the end of the string table")
            return text[st_name:end]
    else:
        def name_of(sym: int) -> str:
            st_name = symbols[sym][0]
            return _name(obj, strings.offset + st_name) if st_name else ""

    n_symbols = len(symbols)
    relocations = []  # (target section, its entries: (offset, type, symbol index, addend))
    for sec in sections:
        if sec.type != SHT_RELA or sec.info >= len(sections):
            continue
        target = sections[sec.info]
        if not target.flags & SHF_ALLOC or _skipped(target):
            continue
        if sections[sec.link] is not table:
            raise Refused(f"{sec.name} names another symbol table")
        if sec.size % _RELA.size:
            raise Refused(f"{sec.name} ends in a partial entry")
        rows = [(r_offset, r_info & 0xFFFFFFFF, r_info >> 32, addend) for r_offset, r_info, addend
                in _RELA.iter_unpack(obj[sec.offset:sec.offset + sec.size])]
        if not rows:
            continue
        types = {row[1] for row in rows}  # checked a section at a time, not an entry
        if not types <= KNOWN:
            raise Refused(f"relocation type {min(types - KNOWN)}")
        if max(row[2] for row in rows) >= n_symbols:
            raise Refused("relocation of a symbol past the table")
        relocations.append((target, rows, types))

    # the layout: executable sections and stubs, read-only sections and GOT, writable
    stubs = sorted({sym for _t, rows, types in relocations if R_X86_64_PLT32 in types
                    for _o, typ, sym, _a in rows
                    if typ == R_X86_64_PLT32 and symbols[sym][3] == SHN_UNDEF})
    got = sorted({sym for _t, rows, types in relocations if not types.isdisjoint(_GOT_TYPES)
                  for _o, typ, sym, _a in rows if typ in _GOT_TYPES})
    where: dict[int, int] = {}  # section index -> offset in the mapping
    size = 0
    groups = []
    for kind in ("x", "r", "w"):
        start = size = _align(size, _PAGE)
        for sec in loaded:
            sec_kind = ("x" if sec.flags & SHF_EXECINSTR else
                        "w" if sec.flags & SHF_WRITE or sec.type == SHT_NOBITS else "r")
            if sec_kind == kind:
                size = _align(size, sec.align)
                where[sec.index] = size
                size += sec.size
        if kind == "x":
            size = _align(size, _STUB)
            stub_at = size
            size += _STUB * len(stubs)
        elif kind == "r":
            size = _align(size, 8)
            got_at = size
            size += 8 * len(got)
        else:
            commons = {}
            for i in [i for i, sym in enumerate(symbols) if sym[3] == SHN_COMMON]:
                value, sz = symbols[i][4:6]
                size = _align(size, max(value, 1))
                commons[i] = size
                size += sz
        groups.append((kind, start, size))
    size = max(_align(size, _PAGE), _PAGE)
    base = _map(size)
    try:
        image = bytearray(size)
        for sec in loaded:
            if sec.type != SHT_NOBITS:
                at = where[sec.index]
                image[at:at + sec.size] = obj[sec.offset:sec.offset + sec.size]
        address: list[int | None] = []
        out: dict[str, int] = {}
        for i, (st_name, info, _other, shndx, value, _sz) in enumerate(symbols):
            bind, typ = info >> 4, info & 0xF
            if typ in (STT_TLS, STT_GNU_IFUNC):
                raise Refused(f"symbol {name_of(i)!r} of type {typ}")
            name = ""  # an undefined symbol's name, read once for both uses
            if shndx == SHN_UNDEF:
                name = name_of(i)
                addr = resolve(name) if name else None
            elif shndx == SHN_ABS:
                addr = value
            elif shndx == SHN_COMMON:
                addr = base + commons[i]
            elif shndx >= SHN_LORESERVE:
                raise Refused(f"symbol {name_of(i)!r} in special section {shndx:#x}")
            else:
                addr = base + where[shndx] + value if shndx in where else None
            address.append(addr)
            if addr is not None and st_name and bind != STB_LOCAL and typ != STT_SECTION:
                name = name or name_of(i)  # a global's name (the locals are never named)
                if name:
                    out[name] = addr
        for n, sym in enumerate(got):
            target = address[sym]
            if target is None:
                raise Refused(f"symbol {name_of(sym)!r} not found")
            _U64.pack_into(image, got_at + 8 * n, target)
        stub_of = {}
        for n, sym in enumerate(stubs):
            target = address[sym]
            if target is None:
                raise Refused(f"symbol {name_of(sym)!r} not found")
            at = stub_at + _STUB * n
            image[at:at + 6] = b"\xff\x25\x00\x00\x00\x00"
            _U64.pack_into(image, at + 6, target)
            stub_of[sym] = base + at
        got_of = {sym: base + got_at + 8 * n for n, sym in enumerate(got)}
        put64 = _U64.pack_into
        for target, rows, _types in relocations:
            start, end = where[target.index], target.size
            for r_offset, typ, sym, addend in rows:
                if typ == R_X86_64_NONE:
                    continue
                s = address[sym]
                if s is None:
                    raise Refused(f"symbol {name_of(sym)!r} not found")
                at = start + r_offset
                if typ == R_X86_64_64:  # nearly all of numba's (its large code model)
                    if r_offset + 8 > end:
                        raise Refused("relocation past its section")
                    put64(image, at, (s + addend) & 0xFFFFFFFFFFFFFFFF)
                    continue
                if r_offset + (8 if typ == R_X86_64_PC64 else 4) > end:
                    raise Refused("relocation past its section")
                _apply(image, at, base + at, typ, s, addend, stub_of.get(sym),
                       got_of.get(sym))
        ctypes.memmove(base, bytes(image), size)
        for kind, start, end in groups:
            prot = {"x": 5, "r": 1, "w": 3}[kind]  # PROT_READ | EXEC, READ, READ | WRITE
            lo, hi = start, _align(end, _PAGE)
            if hi > lo and _libc().mprotect(ctypes.c_void_p(base + lo), hi - lo, prot) != 0:
                raise Refused(f"mprotect refused ({ctypes.get_errno()})")
    except BaseException:
        _libc().munmap(ctypes.c_void_p(base), size)
        raise
    return Linked(base, size, out)


def _apply(image: bytearray, at: int, p: int, typ: int, s: int, a: int,
           stub: int | None, got: int | None) -> None:
    """One relocation at ``image[at]`` (address ``p``) of a symbol at ``s``, addend ``a``."""
    if typ == R_X86_64_64:
        struct.pack_into("<Q", image, at, (s + a) & 0xFFFFFFFFFFFFFFFF)
    elif typ == R_X86_64_PC64:
        struct.pack_into("<Q", image, at, (s + a - p) & 0xFFFFFFFFFFFFFFFF)
    elif typ in (R_X86_64_PC32, R_X86_64_PLT32):
        value = s + a - p
        if typ == R_X86_64_PLT32 and not -2 ** 31 <= value < 2 ** 31 and stub is not None:
            value = stub + a - p
        _put32(image, at, value, signed=True)
    elif typ == R_X86_64_32:
        _put32(image, at, s + a, signed=False)
    elif typ == R_X86_64_32S:
        _put32(image, at, s + a, signed=True)
    elif typ in _GOT_TYPES:
        assert got is not None
        _put32(image, at, got + a - p, signed=True)
    else:  # pragma: no cover - refused before
        raise Refused(f"relocation type {typ}")


def _put32(image: bytearray, at: int, value: int, signed: bool) -> None:
    if signed and not -2 ** 31 <= value < 2 ** 31 or not signed and not 0 <= value < 2 ** 32:
        raise Refused(f"relocation value {value:#x} out of its 32-bit field")
    struct.pack_into("<i" if signed else "<I", image, at, value)


_LIBC: list[ctypes.CDLL] = []


def _libc() -> ctypes.CDLL:
    if not _LIBC:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.mmap.restype = ctypes.c_void_p
        libc.mmap.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
                              ctypes.c_int, ctypes.c_long)
        libc.mprotect.argtypes = (ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int)
        libc.munmap.argtypes = (ctypes.c_void_p, ctypes.c_size_t)
        _LIBC.append(libc)
    return _LIBC[0]


def _map(size: int) -> int:
    """An anonymous private read + write mapping of ``size`` bytes."""
    libc = _libc()
    base = libc.mmap(None, size, 3, 0x22, -1, 0)  # PROT_READ|WRITE, MAP_PRIVATE|ANONYMOUS
    if base is None or base in (0, 2 ** 64 - 1, -1):
        raise Refused(f"mmap refused ({ctypes.get_errno()})")
    return base
