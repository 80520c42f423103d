"""What :mod:`mitld_lp.util.kernel_loader` needs to link a kernel with
:mod:`mitld_lp.util.elf_link` instead of llvmlite: the symbols numba's own load adds to
LLVM's table (:func:`explicit_symbols`), a resolver that asks them first and then the
process (:func:`resolver`, as LLVM's ``DynamicLibrary`` does), and the part of a cache
file's key only llvmlite can compute (LLVM's version, the target triple, CPU name and
features), remembered in a small file written by a process that did set llvmlite up
(:func:`read_machine`, :func:`write_machine`).  That file is keyed by Python's version,
numba's extension files, llvmlite's version and shared library (its size and time), and
the CPU as ``/proc/cpuinfo`` describes it (vendor, family, model, stepping, flags): any
change there and the loader sets llvmlite up again, which rewrites it."""

from __future__ import annotations

import builtins
import ctypes
import hashlib
import importlib.machinery
import importlib.util
import marshal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mitld_lp.util import kernel_files

__all__ = ["explicit_symbols", "load_extensions", "prime_unpickle", "probe", "read_machine",
           "resolver", "write_machine"]


def explicit_symbols(helperlib: Any, nrt: Any, dynfunc: Any) -> dict[str, int]:
    """The symbols numba's load adds (``numba.core.base._load_global_helpers``, the
    runtime's ``rtsys.initialize``): numba's C helpers, NRT's, ``_Py_NoneStruct`` and
    each ``PyExc_*`` as the exception class itself (numba's code takes the global for
    the object, where CPython's symbol is a pointer to it)."""
    out = {"_Py_NoneStruct": id(None)}
    for helpers in (helperlib.c_helpers, dynfunc.c_helpers):
        for name, address in helpers.items():
            out["numba_" + name] = address
    for obj in builtins.__dict__.values():
        if isinstance(obj, type) and issubclass(obj, BaseException):
            out[f"PyExc_{obj.__name__}"] = id(obj)
    for name, address in nrt.c_helpers.items():
        out[name if name.startswith("_") else "NRT_" + name] = address
    return out


def resolver(explicit: dict[str, int]) -> Callable[[str], int | None]:
    """A symbol's address: ``explicit`` first, then the process's (libc, libm, the
    Python C API), None where neither has it.  The process's addresses found are
    remembered: the kernels of a process name mostly the same ones (``dlsym`` through
    ctypes is some microseconds a name)."""
    process = ctypes.CDLL(None)
    found: dict[str, int] = {}

    def resolve(name: str) -> int | None:
        address = explicit.get(name) or found.get(name)
        if address is not None:
            return address
        try:
            address = ctypes.cast(process[name], ctypes.c_void_p).value
        except (AttributeError, ValueError):
            return None
        if address is not None:  # (a name not found may be loaded later: asked again)
            found[name] = address
        return address

    return resolve


def _cpu() -> str:
    """The first processor's identity in ``/proc/cpuinfo`` (what LLVM's host CPU name
    and features follow), or "" where it cannot be read."""
    wanted = ("vendor_id", "cpu family", "model", "model name", "stepping", "flags")
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            block = f.read().split("\n\n", 1)[0]
    except OSError:
        return ""
    lines = []
    for line in block.splitlines():
        name, _, value = line.partition(":")
        if name.strip() in wanted:
            lines.append(f"{name.strip()}:{value.strip()}")
    return "\n".join(lines)


def probe(version: str, numba_id: Any) -> tuple | None:
    """What the remembered machine description is keyed by (module docs), or None."""
    spec = importlib.util.find_spec("llvmlite")
    cpu = _cpu()
    if spec is None or not spec.submodule_search_locations or not cpu:
        return None
    base = Path(list(spec.submodule_search_locations)[0])
    libs = sorted((base / "binding").glob("libllvmlite*"))
    try:
        stamps = tuple((p.name, p.stat().st_size, p.stat().st_mtime_ns) for p in libs)
        llvmlite_version = (base / "_version.py").read_bytes()
    except OSError:
        return None
    if not stamps:
        return None
    return (version, numba_id, hashlib.sha256(llvmlite_version).hexdigest(), stamps,
            hashlib.sha256(cpu.encode()).hexdigest())


def _name(key: tuple) -> str:
    return "kernel_machine-" + hashlib.sha256(repr(key).encode()).hexdigest()[:20] + ".kmach"


def read_machine(key: tuple | None) -> tuple | None:
    """The machine description remembered for ``key``: (llvmlite's version, LLVM's
    version, (triple, CPU name, features)), or None."""
    if key is None:
        return None
    for directory in kernel_files.directories(__file__):
        try:
            found = kernel_files.unpack((directory / _name(key)).read_bytes())
        except OSError:
            continue
        if found is None:
            continue
        meta = found[0]
        if meta.get("probe") == repr(key).encode() and isinstance(meta.get("machine"), tuple):
            return meta["machine"]
    return None


def write_machine(key: tuple | None, machine: tuple) -> None:
    """Remember ``machine`` for ``key`` (nothing where no directory can be written)."""
    if key is None or read_machine(key) == machine:
        return
    data = kernel_files.pack(marshal.dumps({"probe": repr(key).encode(), "machine": machine}),
                             b"")
    for directory in kernel_files.directories(__file__):
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError:
            continue
        kernel_files.write(directory / _name(key), data)
        if read_machine(key) == machine:
            return


# --- numba's extension modules, loaded without numba ------------------------------------


def _numba_dir() -> Path | None:
    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(list(spec.submodule_search_locations)[0])


def _extension(base: Path, rel: str) -> Path | None:
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = base / (rel + suffix)
        if path.is_file():
            return path
    return None


def load_extensions(extensions: tuple) -> tuple[list[Any], tuple] | None:
    """numba's three extension modules (loaded from their shared libraries without
    numba's package where numba is not imported yet: ``import numba`` later finds and
    keeps them, CPython initialises such a module once), and what identifies them."""
    base = _numba_dir()
    if base is None:
        return None
    mods, stamps = [], []
    for name, rel in extensions:
        path = _extension(base, rel)
        if path is None:
            return None
        st = path.stat()
        stamps.append((rel, st.st_size, st.st_mtime_ns))
        mod = sys.modules.get(name)
        if mod is None:
            loader = importlib.machinery.ExtensionFileLoader(name, str(path))
            spec = importlib.util.spec_from_file_location(name, str(path), loader=loader)
            if spec is None:
                return None
            mod = importlib.util.module_from_spec(spec)
            loader.exec_module(mod)
            sys.modules[name] = mod
        mods.append(mod)
    try:
        version = (base / "_version.py").read_bytes()
    except OSError:
        return None
    return mods, (hashlib.sha256(version).hexdigest(), tuple(stamps))


_unpickled_memo: dict[tuple, Any] = {}


def _numba_unpickle(address: int, bytedata: bytes, hashed: bytes) -> Any:
    """numba's ``numba.core.serialize._numba_unpickle`` (numba 0.68), line for line:
    ``numba_unpickle`` of ``numba._helperlib`` calls it for the constants a wrapper boxes
    with (the class of the arrays it returns) and keeps it for the process
    ((:func:`prime_unpickle`)); numba's vendored cloudpickle's ``loads`` is pickle's."""
    import pickle

    key = (address, hashed)
    try:
        obj = _unpickled_memo[key]
    except KeyError:
        _unpickled_memo[key] = obj = pickle.loads(bytedata)
    return obj


def prime_unpickle(address: int) -> bool:
    """Have ``numba_unpickle`` of ``numba._helperlib`` fetch its Python function now, from
    a stand-in of ``numba.core.serialize`` holding :func:`_numba_unpickle` alone (and
    empty stand-ins of its parents, which ``PyImport_ImportModule`` imports first), put in
    ``sys.modules`` for this one call under the import lock: the helper imports that
    module once a process and keeps the function (a static of the C helper), and the real
    module imports all of numba.  Where numba is loaded already nothing is done (the
    helper takes numba's)."""
    import _imp
    import ctypes
    import pickle
    import types

    names = ("numba", "numba.core", "numba.core.serialize")
    if "numba" in sys.modules:
        return True
    stand_ins = {name: types.ModuleType(name) for name in names}
    stand_ins["numba.core.serialize"]._numba_unpickle = _numba_unpickle  # type: ignore[attr-defined]
    for name in names[:2]:
        stand_ins[name].__path__ = []  # type: ignore[attr-defined]  # a package: no finder
    proto = ctypes.PYFUNCTYPE(ctypes.py_object, ctypes.c_char_p, ctypes.c_int,
                              ctypes.c_char_p)
    data = pickle.dumps(None)
    _imp.acquire_lock()
    try:
        if any(name in sys.modules for name in names):
            return False
        sys.modules.update(stand_ins)
        try:
            got = proto(address)(data, len(data), b"\0" * 20)
        except Exception:  # noqa: BLE001 - the helper could not be primed: numba's load
            return False
        finally:
            for name in names:
                if sys.modules.get(name) is stand_ins[name]:
                    del sys.modules[name]
    finally:
        _imp.release_lock()
    return got is None
