"""What a first solve pays once (start-85): the ELF linker's names and relocation checks,
and numba's presence looked up once a process.

The linker reads each name of an ASCII string table as a slice of the table decoded
once, and any other table byte by byte; it checks relocation types and symbol indices
a RELA section at a time.  Each object here is assembled by hand, and every address is
checked against the layout computed by hand (the code section first, at the mapping's
start; each name as written into the table)."""

from __future__ import annotations

import ctypes
import json
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.util import elf_link

ROOT = Path(__file__).resolve().parent.parent
FAR = 0x7F12_3456_7000  # an external function beyond 2 GiB of any mapping

needs_x86_linux = pytest.mark.skipif(not elf_link.supported(), reason="x86-64 Linux only")


def _assemble(strtab: bytes, symbols: list[tuple[int, int, int, int]],
              relocs: dict[int, list[tuple[int, int, int, int]]]) -> bytes:
    """An ELF64 x86-64 relocatable object: section 1 ``.text`` (64 bytes 0xCC), section
    2 ``.text.b`` (32 bytes 0x90), both executable, after a null symbol ``symbols``
    (``st_name``, info, section index, value) with ``strtab`` as their string table, and
    for each code section index in ``relocs`` a RELA section of (offset, type, symbol
    index, addend)."""
    blobs = [b"\xcc" * 64, b"\x90" * 32]
    names = [".text", ".text.b", ".symtab", ".strtab", ".shstrtab"]
    rela_of = sorted(relocs)
    names += [f".rela{names[i - 1]}" for i in rela_of]
    shstr = b"\0" + b"".join(n.encode() + b"\0" for n in names)
    at = {n: shstr.index(b"\0" + n.encode() + b"\0") + 1 for n in names}
    symtab = struct.pack("<IBBHQQ", 0, 0, 0, 0, 0, 0) + b"".join(
        struct.pack("<IBBHQQ", st_name, info, 0, shndx, value, 0)
        for st_name, info, shndx, value in symbols)
    blobs += [symtab, strtab, shstr]
    blobs += [b"".join(struct.pack("<QQq", off, (sym << 32) | typ, add)
                       for off, typ, sym, add in relocs[i]) for i in rela_of]
    out, offsets = bytearray(64), []  # the header written last, over these 64 bytes
    for b in blobs:
        out += bytes(-len(out) % 16)
        offsets.append(len(out))
        out += b
    out += bytes(-len(out) % 8)
    kinds = {  # sh_type, sh_flags, sh_link, sh_info, sh_addralign, sh_entsize
             "code": (1, 6, 0, 0, 16, 0), "symtab": (2, 0, 4, 1, 8, 24),
             "strtab": (3, 0, 0, 0, 1, 0)}
    plan = [(".text", "code"), (".text.b", "code"), (".symtab", "symtab"),
            (".strtab", "strtab"), (".shstrtab", "strtab")]
    table = [bytes(64)]
    for k, (name, kind) in enumerate(plan):
        typ, flags, link, info, align, entsize = kinds[kind]
        table.append(struct.pack("<IIQQQQIIQQ", at[name], typ, flags, 0, offsets[k],
                                 len(blobs[k]), link, info, align, entsize))
    for k, i in enumerate(rela_of):
        table.append(struct.pack("<IIQQQQIIQQ", at[names[5 + k]], 4, 0x40, 0, offsets[5 + k],
                                 len(blobs[5 + k]), 3, i, 8, 24))
    out[:64] = (b"\x7fELF\x02\x01\x01" + bytes(9)
                + struct.pack("<HHIQQQIHHHHHH", 1, 62, 1, 0, 0, len(out), 0, 64, 0, 0, 64,
                              len(table), 5))
    return bytes(out + b"".join(table))


GLOBAL_FUNC, GLOBAL_NOTYPE = 0x12, 0x10


def _u64(addr: int) -> int:
    return struct.unpack("<Q", ctypes.string_at(addr, 8))[0]


@needs_x86_linux
def test_names_of_an_ascii_table_shared_suffixes_included() -> None:
    # "entry_point" at 1; "point" is its suffix, at 7; "far" at 13
    strtab = b"\0entry_point\0far\0"
    symbols = [(1, GLOBAL_FUNC, 1, 8),  # 1: entry_point at .text+8
               (7, GLOBAL_FUNC, 2, 4),  # 2: point at .text.b+4 (the name's tail)
               (13, GLOBAL_NOTYPE, 0, 0)]  # 3: far, undefined
    asked = []

    def resolve(name: str) -> int | None:
        asked.append(name)
        return FAR if name == "far" else None

    linked = elf_link.link(_assemble(strtab, symbols, {1: [(0, 1, 3, 5)], 2: [(8, 1, 1, 0)]}),
                           resolve)
    base = linked.base  # .text first at the mapping's start, .text.b 16-aligned after it
    assert linked.symbols == {"entry_point": base + 8, "point": base + 64 + 4, "far": FAR}
    assert asked == ["far"]
    assert _u64(base) == FAR + 5  # R_X86_64_64 in .text: S + A
    assert _u64(base + 64 + 8) == base + 8  # R_X86_64_64 in .text.b, to entry_point


@needs_x86_linux
@needs_x86_linux
def test_names_of_a_table_not_ascii() -> None:
    names = ["fonction_é", "ünter"]
    strtab = b"\0" + b"".join(n.encode() + b"\0" for n in names)
    first, second = 1, 1 + len(names[0].encode()) + 1
    linked = elf_link.link(_assemble(strtab, [(first, GLOBAL_FUNC, 1, 0),
                                              (second, GLOBAL_FUNC, 2, 16)], {}),
                           lambda name: None)
    assert linked.symbols == {"fonction_é": linked.base, "ünter": linked.base + 64 + 16}


@needs_x86_linux
def test_a_name_past_its_table_is_refused() -> None:
    strtab = b"\0abc"  # no terminating NUL
    with pytest.raises(elf_link.Refused, match="past the end"):
        elf_link.link(_assemble(strtab, [(1, GLOBAL_FUNC, 1, 0)], {}), lambda name: None)


@needs_x86_linux
def test_relocations_checked_in_each_section() -> None:
    strtab = b"\0f\0far\0"
    symbols = [(1, GLOBAL_FUNC, 1, 0), (3, GLOBAL_NOTYPE, 0, 0)]  # 1: f, 2: far
    good = [(0, 1, 2, 0)]

    def resolve(name: str) -> int | None:
        return FAR if name == "far" else None

    for bad in ((8, 23, 2, 0),  # R_X86_64_TPOFF32: a type it does not apply
                (8, 1, 3, 0),  # a symbol past the table
                (28, 1, 2, 0)):  # 8 bytes at 28 of the 32-byte .text.b
        for relocs in ({1: good, 2: [bad]}, {2: [*good, bad]}, {2: [bad, *good]}):
            with pytest.raises(elf_link.Refused):
                elf_link.link(_assemble(strtab, symbols, relocs), resolve)
    linked = elf_link.link(_assemble(strtab, symbols, {1: good, 2: [(24, 1, 2, -1)]}), resolve)
    assert _u64(linked.base) == FAR and _u64(linked.base + 64 + 24) == FAR - 1


def test_numba_found_once_a_process() -> None:
    """Every kernel module imported before numba asked numba's finders again (0.15 ms
    each); now once.  In a child: the finders counted while five kernel modules import."""
    code = """
import importlib.util, json, sys
calls = []
real = importlib.util.find_spec
def counted(name, *args):
    if name == "numba":
        calls.append(name)
    return real(name, *args)
importlib.util.find_spec = counted
import mitld_lp.util.kernel_loader
for m in ("mitld_lp.product.bfs_kernels", "mitld_lp.solvers.certify_kernels",
          "mitld_lp.solvers.certify_repair_kernels", "mitld_lp.solvers.lift_kernels",
          "mitld_lp.solvers.level_kernels"):
    importlib.import_module(m)
print(json.dumps({"found": len(calls), "numba": "numba" in sys.modules,
                  "installed": real("numba") is not None}))
"""
    got = json.loads(subprocess.run([sys.executable, "-c", "import importlib\n" + code],
                                    cwd=ROOT, capture_output=True, text=True, check=True,
                                    timeout=120).stdout)
    if not got["installed"]:
        pytest.skip("numba is not installed")
    assert not got["numba"]  # the kernel modules imported without numba
    assert got["found"] <= 1


def test_the_reversed_walks_signature_is_warmed() -> None:
    """zeroconf 20-4 ``correct_min`` compiled ``compiled_graph.reaching_edges`` in its
    solve after ``mitld-lp warm`` (wide-84, on 95e98cc: 2.4 s of solve against 0.7): a
    minimum's Prob1A search walks the reversed edges compiled from 150,000 entries once the
    loader is set up, and warm did not list the signature that walk calls.  Here the
    arguments each caller of the compiled walk gives are recorded and their type key
    looked up in warm's list."""
    import numpy as np
    import scipy.sparse as sp

    from mitld_lp.solvers import reach
    from mitld_lp.util import warm_kernels
    from mitld_lp.util.kernel_types import type_key

    seen = []

    class Walks:
        @staticmethod
        def reaching_edges(*args: object) -> np.ndarray:
            seen.append(warm_kernels.encode(type_key(args)))
            return np.zeros(int(args[0]), dtype=bool)

    listed = {key for m, n, key in warm_kernels.signatures()
              if (m, n) == ("mitld_lp.solvers.compiled_graph", "reaching_edges")}
    real = reach.compiled_walks
    reach.compiled_walks = lambda entries: Walks
    try:
        seeds = np.array([False, True, False])
        reach.backward_reachable(3, np.array([0, 2]), np.array([1, 1]), seeds)
        m = sp.csr_array(np.array([[0.5, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
        reach.reaching_through(m, np.array([0, 1, 2, 3]), np.array([True, True, True]), seeds)
    finally:
        reach.compiled_walks = real
    assert seen and {warm_kernels.encode(k) for k in listed} >= set(seen), (seen, listed)
