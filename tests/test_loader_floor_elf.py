"""The kernel loader's own ELF linker (mitld_lp.util.elf_link): each relocation type it
applies, checked against a value computed by hand on a tiny object assembled here; the
relocations of a real cache file read back from memory against their symbols' addresses
(the file parsed here, readelf-style); the fallback to llvmlite on a relocation type it
does not know; a kernel linked by it and by llvmlite (forced) giving numba's outputs to
the bit; and a warm process that links by it never importing llvmlite."""

from __future__ import annotations

import ctypes
import json
import os
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.util import elf_link, elf_runtime, kernel_files

ROOT = Path(__file__).resolve().parent.parent

needs_x86_linux = pytest.mark.skipif(not elf_link.supported(), reason="x86-64 Linux only")

# --- a tiny object assembled by hand ----------------------------------------------------

FAR = 0x7F12_3456_7000  # an external function beyond 2 GiB of any mapping of ours
SMALL = 0x1234  # an external absolute value that fits 32 bits


def _strtab(names: list[str]) -> tuple[bytes, dict[str, int]]:
    data, where = b"\0", {}
    for n in names:
        where[n] = len(data)
        data += n.encode() + b"\0"
    return data, where


def _object(relocs: list[tuple[int, int, str, int]]) -> bytes:
    """An ELF64 x86-64 relocatable object: .text (64 bytes 0xCC, executable), .data (16
    bytes 0..15, writable, symbol ``data_sym`` at 4), a function ``fn`` at .text+8, the
    externals ``far`` and ``small``, and ``relocs`` (offset in .text, type, symbol,
    addend) in .rela.text."""
    text = b"\xcc" * 64
    data = bytes(range(16))
    sec_names = ["", ".text", ".data", ".rela.text", ".symtab", ".strtab", ".shstrtab"]
    shstr, sh_at = _strtab(sec_names[1:])
    sym_names = ["fn", "data_sym", "far", "small"]
    strtab, st_at = _strtab(sym_names)
    # symbols: null, section .text (local), then globals fn, data_sym, far, small
    syms = [(0, 0, 0, 0, 0, 0), (0, 3, 0, 1, 0, 0),
            (st_at["fn"], 0x12, 0, 1, 8, 4), (st_at["data_sym"], 0x11, 0, 2, 4, 4),
            (st_at["far"], 0x10, 0, 0, 0, 0), (st_at["small"], 0x10, 0, 0, 0, 0)]
    index = {"fn": 2, "data_sym": 3, "far": 4, "small": 5}
    symtab = b"".join(struct.pack("<IBBHQQ", *s) for s in syms)
    rela = b"".join(struct.pack("<QQq", off, (index[sym] << 32) | typ, add)
                    for off, typ, sym, add in relocs)
    blobs = [text, data, rela, symtab, strtab, shstr]
    offsets, pos = [], 64
    for b in blobs:
        pos = (pos + 15) // 16 * 16
        offsets.append(pos)
        pos += len(b)
    shoff = (pos + 7) // 8 * 8
    # name, type, flags, addr, offset, size, link, info, align, entsize
    heads = [(0,) * 10,
             (sh_at[".text"], 1, 6, 0, offsets[0], len(text), 0, 0, 16, 0),
             (sh_at[".data"], 1, 3, 0, offsets[1], len(data), 0, 0, 8, 0),
             (sh_at[".rela.text"], 4, 0x40, 0, offsets[2], len(rela), 4, 1, 8, 24),
             (sh_at[".symtab"], 2, 0, 0, offsets[3], len(symtab), 5, 2, 8, 24),
             (sh_at[".strtab"], 3, 0, 0, offsets[4], len(strtab), 0, 0, 1, 0),
             (sh_at[".shstrtab"], 3, 0, 0, offsets[5], len(shstr), 0, 0, 1, 0)]
    header = (b"\x7fELF\x02\x01\x01" + b"\0" * 9
              + struct.pack("<HHIQQQIHHHHHH", 1, 62, 1, 0, 0, shoff, 0, 64, 0, 0, 64,
                            len(heads), 6))
    out = bytearray(shoff + 64 * len(heads))
    out[:64] = header
    for off, b in zip(offsets, blobs, strict=True):
        out[off:off + len(b)] = b
    for i, h in enumerate(heads):
        struct.pack_into("<IIQQQQIIQQ", out, shoff + 64 * i, *h)
    return bytes(out)


def _resolve(name: str) -> int | None:
    return {"far": FAR, "small": SMALL}.get(name)


def _u64(addr: int) -> int:
    return struct.unpack("<Q", ctypes.string_at(addr, 8))[0]


def _i32(addr: int) -> int:
    return struct.unpack("<i", ctypes.string_at(addr, 4))[0]


@needs_x86_linux
def test_each_relocation_type_by_hand() -> None:
    relocs = [(0, 1, "far", 5),  # R_X86_64_64: S + A
              (8, 24, "data_sym", 3),  # PC64: S + A - P
              (16, 2, "data_sym", -4),  # PC32: S + A - P (same mapping: fits)
              (20, 4, "far", -4),  # PLT32 to a far function: through a stub
              (24, 10, "small", 2),  # 32: S + A, unsigned
              (28, 11, "small", -0x2000),  # 32S: S + A, signed
              (32, 9, "far", -4),  # GOTPCREL: GOT slot + A - P, the slot holding S
              (36, 42, "data_sym", -4),  # REX_GOTPCRELX: the same (not relaxed)
              (40, 41, "fn", -4),  # GOTPCRELX of a defined function
              (44, 4, "fn", -4)]  # PLT32 to a defined, near function: direct
    linked = elf_link.link(_object(relocs), _resolve)
    fn = linked.symbols["fn"]
    data_sym = linked.symbols["data_sym"]
    text = fn - 8
    assert ctypes.string_at(data_sym - 4, 16) == bytes(range(16))  # .data copied
    assert ctypes.string_at(text + 48, 16) == b"\xcc" * 16  # untouched bytes copied
    assert _u64(text) == FAR + 5
    assert _u64(text + 8) == (data_sym + 3 - (text + 8)) % 2 ** 64
    assert _i32(text + 16) == data_sym - 4 - (text + 16)
    stub = text + 20 + 4 + _i32(text + 20)  # where the call lands
    assert ctypes.string_at(stub, 6) == b"\xff\x25\x00\x00\x00\x00"  # jmp *0(%rip)
    assert _u64(stub + 6) == FAR
    assert struct.unpack("<I", ctypes.string_at(text + 24, 4))[0] == 0x1236
    assert _i32(text + 28) == 0x1234 - 0x2000
    assert _u64(text + 32 + 4 + _i32(text + 32)) == FAR  # the GOT slot
    assert _u64(text + 36 + 4 + _i32(text + 36)) == data_sym
    assert _u64(text + 40 + 4 + _i32(text + 40)) == fn
    assert text + 44 + 4 + _i32(text + 44) == fn
    maps = Path("/proc/self/maps").read_text().splitlines()

    def perms(addr: int) -> str:
        for line in maps:
            lo, hi = (int(x, 16) for x in line.split()[0].split("-"))
            if lo <= addr < hi:
                return line.split()[1]
        raise AssertionError(f"{addr:#x} not mapped")

    assert perms(text) == "r-xp"  # code executable, not writable
    assert perms(data_sym) == "rw-p"


def test_refusals() -> None:
    obj = _object([(0, 1, "far", 0)])
    with pytest.raises(elf_link.Refused):  # R_X86_64_TPOFF32: not a type it applies
        elf_link.link(_object([(0, 23, "far", 0)]), _resolve)
    with pytest.raises(elf_link.Refused):  # a symbol nobody defines
        elf_link.link(obj, lambda name: None)
    with pytest.raises(elf_link.Refused):  # 32S of a far address does not fit
        elf_link.link(_object([(0, 11, "far", 0)]), _resolve)
    with pytest.raises(elf_link.Refused):  # PC32 to far data cannot take a stub
        elf_link.link(_object([(0, 2, "far", 0)]), _resolve)
    arm = bytearray(obj)
    arm[18:20] = struct.pack("<H", 183)  # EM_AARCH64
    with pytest.raises(elf_link.Refused):
        elf_link.link(bytes(arm), _resolve)
    with pytest.raises(elf_link.Refused):
        elf_link.link(b"\0" * 100, _resolve)


def test_a_table_of_a_partial_entry_is_refused() -> None:
    obj = bytearray(_object([(0, 1, "far", 0), (8, 1, "small", 0)]))
    shoff = struct.unpack_from("<Q", obj, 0x28)[0]
    for section, entry in ((3, 24), (4, 24)):  # .rela.text, .symtab
        bad = bytearray(obj)
        at = shoff + 64 * section + 32  # sh_size
        size = struct.unpack_from("<Q", bad, at)[0]
        struct.pack_into("<Q", bad, at, size - entry // 2)
        with pytest.raises(elf_link.Refused, match="partial entry"):
            elf_link.link(bytes(bad), _resolve)


# --- real kernels -----------------------------------------------------------------------

pytest.importorskip("numba")
from mitld_lp.solvers import compiled_graph  # noqa: E402
from mitld_lp.util import kernel_loader  # noqa: E402

no_numba_settings = pytest.mark.skipif(
    any(k.startswith("NUMBA_") and k != "NUMBA_CACHE_DIR" for k in os.environ),
    reason="a NUMBA_* setting leaves every kernel to numba")


def _graph(rng: np.random.Generator, n: int, p: float) -> tuple:
    g = sp.csr_array((rng.random((n, n)) < p).astype(np.int8))
    return g.indptr.astype(np.int64), g.indices.astype(np.int64), np.bool_(False)


def _cache_file(kernel: kernel_loader.Kernel, args: tuple) -> tuple[tuple, bytes]:
    key = kernel_loader.type_key(args)
    kernel(*args)  # a miss: numba's call writes the file
    py = kernel.py_func.__code__.co_filename
    name = kernel_files.file_name(py, kernel.__qualname__, key)
    for d in kernel_files.directories(py):
        if (d / name).is_file():
            return key, (d / name).read_bytes()
    raise AssertionError("no cache file written")


@needs_x86_linux
@no_numba_settings
def test_real_object_relocations_read_back() -> None:
    """Every R_X86_64_64 of a real kernel's code, read back after the link, holds its
    symbol's address plus the addend: externals by the process's ``dlsym`` or numba's
    helper tables, the object's own symbols by the address of the code section."""
    args = _graph(np.random.default_rng(3), 40, 0.05)
    _key, data = _cache_file(compiled_graph.strong_components, args)
    meta, obj = kernel_files.unpack(data)
    shoff, = struct.unpack_from("<Q", obj, 40)
    shnum, shstrndx = struct.unpack_from("<HH", obj, 60)
    secs = [struct.unpack_from("<IIQQQQIIQQ", obj, shoff + 64 * i) for i in range(shnum)]

    def cstr(at: int) -> str:
        return obj[at:obj.index(b"\0", at)].decode()

    names = [cstr(secs[shstrndx][4] + s[0]) for s in secs]
    symtab = next(s for s in secs if s[1] == 2)
    syms = [struct.unpack_from("<IBBHQQ", obj, off)
            for off in range(symtab[4], symtab[4] + symtab[5], 24)]
    sym_name = [cstr(secs[symtab[6]][4] + s[0]) if s[0] else "" for s in syms]
    rt = kernel_loader._setup()
    assert rt is not None
    resolve = elf_runtime.resolver(rt.symbols)
    linked = elf_link.link(obj, resolve)
    text_index = names.index(".ltext")
    wrapper = sym_name.index(meta["wrapper"])
    base = linked.symbols[meta["wrapper"]] - syms[wrapper][4]  # .ltext's address
    process = ctypes.CDLL(None)
    checked = 0
    rela = secs[names.index(".rela.ltext")]
    for off in range(rela[4], rela[4] + rela[5], 24):
        r_off, info, addend = struct.unpack_from("<QQq", obj, off)
        assert info & 0xFFFFFFFF == 1  # numba's large code model: R_X86_64_64 only
        s = syms[info >> 32]
        name = sym_name[info >> 32]
        if s[3] == 0:  # undefined
            expected = rt.symbols.get(name) or ctypes.cast(process[name], ctypes.c_void_p).value
        elif s[3] == text_index:
            expected = base + s[4]
        else:
            continue  # read-only data: its placement is the linker's
        assert _u64(base + r_off) == (expected + addend) % 2 ** 64, name
        checked += 1
    assert checked > 10


@needs_x86_linux
@no_numba_settings
def test_elf_and_llvmlite_links_equal_numba(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(11)
    kernel = compiled_graph.strong_components
    key, data = _cache_file(kernel, _graph(rng, 5, 0.3))
    calls = {}
    for linker in ("elf", "llvm"):
        monkeypatch.setattr(kernel_loader, "LINKER", linker)
        monkeypatch.setattr(kernel_loader, "_linked", {})  # link the object again
        before = kernel_loader.loaded_count(elf=True), kernel_loader.loaded_count()
        calls[linker] = kernel_loader._link(kernel, key, data)
        assert calls[linker] is not None
        after = kernel_loader.loaded_count(elf=True), kernel_loader.loaded_count()
        assert after == (before[0] + (linker == "elf"), before[1] + 1)
    for n, p in [(1, 0.5), (50, 0.04), (300, 0.01), (600, 0.003)]:
        args = _graph(rng, n, p)
        numba_says = kernel.numba_dispatcher()(*args)
        for call in calls.values():
            got = call(*args)
            assert got[0] == numba_says[0]
            np.testing.assert_array_equal(got[1], numba_says[1])
            assert got[1].dtype == numba_says[1].dtype


@needs_x86_linux
@no_numba_settings
def test_unknown_relocation_type_falls_back_to_llvmlite(monkeypatch: pytest.MonkeyPatch) -> None:
    """With R_X86_64_64 taken out of the types it knows, the linker refuses every
    kernel (numba's code is all R_X86_64_64): the loader links by llvmlite instead."""
    rng = np.random.default_rng(5)
    kernel = compiled_graph.strong_components
    key, data = _cache_file(kernel, _graph(rng, 5, 0.3))
    monkeypatch.setattr(elf_link, "KNOWN", elf_link.KNOWN - {elf_link.R_X86_64_64})
    monkeypatch.setattr(kernel_loader, "LINKER", "elf")
    monkeypatch.setattr(kernel_loader, "_linked", {})
    before = kernel_loader.loaded_count(elf=True), kernel_loader.loaded_count()
    call = kernel_loader._link(kernel, key, data)
    assert call is not None
    assert (kernel_loader.loaded_count(elf=True), kernel_loader.loaded_count()) == (
        before[0], before[1] + 1)
    assert "llvmlite.binding" in sys.modules
    args = _graph(rng, 200, 0.01)
    got, numba_says = call(*args), kernel.numba_dispatcher()(*args)
    assert got[0] == numba_says[0]
    np.testing.assert_array_equal(got[1], numba_says[1])


CHILD = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.solvers import compiled_graph
from mitld_lp.util import kernel_loader
g = sp.csr_array(np.array([[0, 1, 0], [1, 0, 0], [0, 0, 0]], dtype=np.int8))
n, labels = compiled_graph.strong_components(g.indptr.astype(np.int64),
                                             g.indices.astype(np.int64), np.bool_(False))
print(json.dumps({"n": int(n), "labels": labels.tolist(), "elf": kernel_loader.loaded_count(True),
                  "llvmlite": sorted(m for m in sys.modules if m.startswith("llvmlite")),
                  "numba": "numba" in sys.modules}))
"""


@needs_x86_linux
@no_numba_settings
def test_warm_process_never_imports_llvmlite() -> None:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    env.pop("MITLD_LP_KERNEL_LINKER", None)
    env.pop("MITLD_LP_KERNEL_LOADER", None)
    outs = []
    for _ in range(3):  # the first may compile (numba) or learn the machine (llvmlite)
        done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True,
                              env=env, cwd="/", check=True)
        outs.append(json.loads(done.stdout.strip().splitlines()[-1]))
    last = outs[-1]
    # two strong components: {0, 1} (a 2-cycle) and {2}; numbered as Tarjan's finishes
    assert last["n"] == 2 and last["labels"][0] == last["labels"][1] != last["labels"][2]
    assert last["elf"] == 1
    assert last["llvmlite"] == [] and not last["numba"]


@no_numba_settings
def test_remembered_machine_is_llvmlites() -> None:
    """The machine description the linker keys by without llvmlite is what llvmlite
    itself says (asked here in a child)."""
    rt = kernel_loader._setup()
    assert rt is not None and kernel_loader._parts(rt) is not None
    code = ("import json, llvmlite; from llvmlite import binding as ll; "
            "ll.initialize_native_target(); ll.initialize_native_asmprinter(); "
            "print(json.dumps([llvmlite.__version__, list(ll.llvm_version_info), "
            "ll.get_process_triple(), ll.get_host_cpu_name(), "
            "ll.get_host_cpu_features().flatten()]))")
    said = json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True,
                                     text=True, check=True).stdout)
    parts = kernel_loader._parts(rt)
    assert [parts[2], list(parts[3]), *parts[4]] == said
    machine = elf_runtime.read_machine(rt.probe)
    assert machine is not None and [machine[0], list(machine[1]), *machine[2]] == said
