"""numba's runtime (NRT) loaded as machine code from a disk cache, not compiled each process.

A kernel loaded from numba's disk cache needs numba's runtime: the C allocator's symbols
and a small LLVM module of its own (atomic reference counts, ``NRT_incref`` /
``NRT_decref``, ``NRT_MemInfo_data_fast``, the unresolved-symbol abort) that every
kernel's machine code calls.  numba compiles that module in every process
(``numba.core.runtime.nrt._Runtime.initialize``): the first use of LLVM's optimiser and
its x86 code generator, measured 0.042 s of CPU and 29 MB of resident memory (LLVM's own
code pages touched) in a process whose kernels all come from the cache
(``experiments/numba_load.py``, 2026-11-30).  Loading that module's object code instead,
as numba loads a cached kernel's (``CodeLibrary._unserialize``, kind ``object``), takes
0.011 s and 10 MB.

:func:`initialize` does what numba's ``initialize`` does (the NRT statistics switch, the
C helpers' symbols, the module's library kept as ``rtsys.library``), with the library
read from a cache file where the file's key is *exactly* this process's: numba's and
llvmlite's versions, LLVM's, the code generator's ``magic_tuple`` (target triple, CPU
name, CPU features: what numba's own cache keys a kernel's machine code by) and the
module's whole LLVM IR text, as this numba builds it now.  Anything else (no file, another
key, a payload whose SHA-256 differs, a file that cannot be read) compiles the module as
numba does and writes the file again (a temporary file renamed over it, so that a reader
never sees half of one).  The machine code is therefore the code this numba would compile
on this CPU; the kernels call it as they call numba's own.  The file sits where numba
puts this package's kernel caches (its own locators: ``NUMBA_CACHE_DIR``, the package's
``__pycache__``, or the user's cache directory); where none is writable the module is
compiled as before.

Only :mod:`mitld_lp.util.numba_narrow`'s load of a cached kernel calls it; a process
that compiles a kernel first initialises the runtime the usual way, and then
:func:`initialize` finds it done.
"""

from __future__ import annotations

import hashlib
import struct
from pathlib import Path
from typing import Any

from mitld_lp.util import kernel_files

__all__ = ["MAGIC", "cache_file", "initialize", "runtime_key"]

MAGIC = b"mitld_lp NRT object 1\n"
"""The first bytes of a cache file (its layout: :func:`_pack`)."""

_HEADER = struct.Struct("<QQQ")  # lengths of the key, the object code, the bitcode


def _anchor() -> None:
    """A function of this module, for numba's cache locators (they locate by function)."""


def cache_file(name: str = "nrt") -> Path | None:
    """Where the runtime's cache file of this key name goes (``name-<hash>.bin`` is put
    in the directory numba's locators give this module); None where no locator applies."""
    from numba.core import caching

    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    for cls in getattr(impl, "_locator_classes", ()):
        locator = cls.from_function(_anchor, __file__)
        if locator is not None:
            try:
                locator.ensure_cache_path()
            except OSError:
                return None
            return Path(locator.get_cache_path()) / name
    return None


def runtime_key(ctx: Any, ir_text: str) -> bytes:
    """The key a cache file must carry to be loaded in this process (module docs)."""
    import llvmlite
    import numba
    from llvmlite import binding as ll

    return repr((numba.__version__, llvmlite.__version__, tuple(ll.llvm_version_info),
                 tuple(ctx.codegen().magic_tuple()), ir_text)).encode()


def _pack(key: bytes, object_code: bytes, bitcode: bytes) -> bytes:
    payload = key + object_code + bitcode
    return (MAGIC + _HEADER.pack(len(key), len(object_code), len(bitcode))
            + hashlib.sha256(payload).digest() + payload)


def _unpack(data: bytes, key: bytes) -> tuple[bytes, bytes] | None:
    """The object code and bitcode of a cache file's bytes, or None unless the file is
    whole, of this layout and of exactly ``key``."""
    start = len(MAGIC) + _HEADER.size + 32
    if len(data) < start or not data.startswith(MAGIC):
        return None
    nk, no, nb = _HEADER.unpack_from(data, len(MAGIC))
    payload = data[start:]
    if len(payload) != nk + no + nb:
        return None
    if hashlib.sha256(payload).digest() != data[start - 32:start]:
        return None
    if payload[:nk] != key:
        return None
    return payload[nk:nk + no], payload[nk + no:]


def _library(ctx: Any) -> Any:
    """The runtime module's library: from the cache file where its key is this
    process's, else compiled (numba's ``compile_nrt_functions``) and written there."""
    from numba.core.runtime import nrtdynmod

    ir_mod, library = nrtdynmod.create_nrt_module(ctx)
    key = runtime_key(ctx, str(ir_mod))
    base = cache_file()
    path = None if base is None else base.with_name(
        f"{base.name}-{hashlib.sha256(key).hexdigest()[:24]}.bin")
    if path is not None:
        try:
            found = _unpack(path.read_bytes(), key)
        except OSError:
            found = None
        if found is not None:
            return ctx.codegen().unserialize_library((library.name, "object", found))
    library.enable_object_caching()
    library.add_ir_module(ir_mod)
    library.finalize()
    if path is not None:
        _name, _kind, (object_code, bitcode) = library.serialize_using_object_code()
        kernel_files.write(path, _pack(key, object_code, bitcode))
    return library


def initialize(ctx: Any) -> None:
    """numba's ``rtsys.initialize(ctx)`` with the runtime's module from the cache (module
    docs); nothing where the runtime is initialised already."""
    from llvmlite import binding as ll
    from numba.core import config
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.runtime import _nrt_python as _nrt
    from numba.core.runtime import rtsys

    with global_compiler_lock:
        if rtsys._init:
            return
        if config.NRT_STATS:
            _nrt.memsys_enable_stats()
        for py_name, address in _nrt.c_helpers.items():
            ll.add_symbol(py_name if py_name.startswith("_") else "NRT_" + py_name, address)
        rtsys._library = _library(ctx)
        rtsys._init = True
