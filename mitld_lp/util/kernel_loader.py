"""numba's cached kernels run without importing numba: numba's own machine code, linked
from a cache of our own (without llvmlite where it can), numba itself only on a miss.

A process that solves a large product imports numba (0.14 s of CPU, numba 0.68) only to
read machine code numba compiled in an earlier process from its disk cache.  That code
needs, at run time, not numba's compiler but four things: the C helpers of three of
numba's extension modules (``numba._helperlib``: raising, the GIL, unpickling an
exception; ``numba.core.runtime._nrt_python``: numba's runtime, NRT, its allocator and
the adaptors between NumPy arrays and NRT's; ``numba._dynfunc``: the environment object
and the closure that calls a CPython wrapper), each loaded here from its shared library
*without* running ``numba/__init__.py``; the process's own Python C API; a runtime linker
(:mod:`mitld_lp.util.elf_link`, or llvmlite's, 0.02 s and 40 MB); and, per kernel, its
environment (the module's globals and the constants its wrapper boxes with: the NumPy
dtypes of the arrays it returns).  numba's runtime's own LLVM module is not needed: each
kernel's object defines the ``NRT_incref`` / ``NRT_decref`` it calls.

A module of kernels says ``numba = kernel_loader.lazy_numba(globals())`` instead of
importing numba; its ``@numba.njit(...)`` lines are unchanged and make :class:`Kernel`
objects.  A kernel's call computes the numba type of each argument with NumPy alone
(:func:`type_key`: an array's dtype, dimensions, layout, read-only and alignment flags,
as ``numba.typeof``); where the cache file of that signature exists and its key is this
process's exactly (:func:`_runtime_key`: the format, Python's, numba's and llvmlite's
versions and numba's extension files, LLVM's version, the target triple, CPU name and
features as numba's ``magic_tuple`` gives them, the kernel's module source and bytecode,
the argument types; the file also names the source of every other module whose kernels
are compiled into it), its object code is linked once and its CPython wrapper called, the
wrapper numba's dispatcher calls (the one Python function of numba a wrapper reaches, the
unpickling of the class of the arrays it returns, is primed with a copy:
:func:`mitld_lp.util.elf_runtime.prime_unpickle`).  The object is linked by
:mod:`mitld_lp.util.elf_link` (no llvmlite: its library adds about 40 MB to a process;
the key's parts only llvmlite can say are remembered by :mod:`mitld_lp.util.elf_runtime`
from a process that set llvmlite up), by llvmlite's MCJIT where that refuses it or where
:data:`LINKER` says so.  Anything else (no file, another key, a damaged or half-written
file, a symbol the linker would not find, an argument of another kind, any ``NUMBA_*``
setting other than the cache directory or a numba config file, :data:`ENABLED` False) goes
to numba: the kernel's numba dispatcher is made (the kernels stay in their modules'
globals; numba types each as its dispatcher), the call is numba's, and the cache file is
written from numba's own cache entry of that signature (read under
:mod:`mitld_lp.util.numba_cache`'s lock), a temporary file renamed over the old one.  The
machine code that runs is therefore numba's, byte for byte, and so are the results.

Where the cache files go: numba's directory for the kernel's function (its locators:
``NUMBA_CACHE_DIR``, the module's ``__pycache__``, the user's cache directory), so that a
file sits beside numba's ``.nbi`` / ``.nbc`` of the same kernel; a reader looks there in
numba's order.  The file's format: :func:`mitld_lp.util.kernel_files.pack`.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib
import importlib.machinery
import importlib.util
import marshal
import os
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.util import elf_link, elf_runtime, kernel_files, kernel_sources
from mitld_lp.util.kernel_types import type_key

__all__ = ["ENABLED", "Kernel", "LazyNumba", "lazy_numba", "loaded_count", "type_key"]

ENABLED = os.environ.get("MITLD_LP_KERNEL_LOADER", "1") != "0"
"""Whether kernels are read from this module's cache (False: every call is numba's)."""

LINKER = os.environ.get("MITLD_LP_KERNEL_LINKER", "elf")
"""How a cached kernel's object is linked: ``"elf"`` by :mod:`mitld_lp.util.elf_link`
(llvmlite is not imported; llvmlite's linker where it refuses), anything else by
llvmlite's MCJIT (``MITLD_LP_KERNEL_LINKER=llvm``: the tests' way to compare the two)."""

_lock = threading.RLock()
_numba: list[Any] = []  # numba, once some kernel needed it
_loaded = [0, 0]  # kernels linked from this module's cache in this process, by elf_link
_linked: dict[tuple, Any] = {}  # (object's digest, wrapper) -> its call, once linked


def loaded_count(elf: bool = False) -> int:
    """Kernel signatures linked from this module's cache (by ``elf_link`` alone)."""
    return _loaded[1 if elf else 0]


def lazy_numba(module_globals: dict[str, Any]) -> LazyNumba:
    """What a module of kernels calls ``numba``: its ``njit`` makes :class:`Kernel`s; any
    other name is numba's (imported then).
    ImportError where numba is not installed (its importers fall back on that, as on
    ``import numba``), found without importing it."""
    if "numba" not in sys.modules and not _numba_installed():
        raise ImportError("numba is not installed")
    return LazyNumba(module_globals)


_installed: list[bool] = []  # whether numba is installed, looked up once a process


def _numba_installed() -> bool:
    """Whether numba can be imported (asked once, not at each kernel module's import)."""
    if not _installed:
        _installed.append(importlib.util.find_spec("numba") is not None)
    return _installed[0]


def compiled_paid() -> bool:
    """Whether a compiled kernel costs this process no further load than reading it:
    numba is imported, or this module's run-time pieces are set up (numba's helpers,
    the key's parts).  The gates that send mid-sized work to compiled kernels once their load is
    paid ask this (it was ``"numba" in sys.modules``)."""
    return "numba" in sys.modules or bool(_runtime and _runtime[0] and _runtime[0].parts)


def cached(module_file: str, qualname: str) -> bool:
    """Whether the loader could link the kernel ``qualname`` of ``module_file`` from a
    cache file instead of compiling it (a warm cache): the loader is on and a cache file
    of some signature of it exists, not older than ``module_file`` or, if older, made
    from its present text (then touched; an edit makes the load compile).  The gates that
    load a kernel before its load is paid ask this, so a cold cache never costs a compile."""
    if not ENABLED or _numba_settings():
        return False
    stem = kernel_files.file_name(module_file, qualname, ()).rsplit("-", 1)[0]
    source = _mtime(Path(module_file), 0)  # (a source not there counts against nothing)
    older = []
    for d in kernel_files.directories(module_file):
        for f in kernel_files.listing(d).get(stem, ()):  # a folder listed once
            if _mtime(d / f, -1) >= source:
                return True
            older.append(d / f)
    for path in older:  # the source rewritten with the same text (a checkout, a reinstall)
        if _same_source(path, module_file):
            with contextlib.suppress(OSError):
                os.utime(path)  # the times answer from now on
            return True
    return False


def _same_source(path: Path, module_file: str) -> bool:
    """Whether the cache file ``path`` was made from ``module_file``'s present text and
    its callees' (the hashes its key and ``sources`` hold, as :func:`_link` checks)."""
    try:
        found = kernel_files.unpack(path.read_bytes())
        own = kernel_sources.source_hash(module_file).encode()
    except OSError:
        return False
    meta = {} if found is None else found[0]
    key, sources = meta.get("key"), meta.get("sources", ())
    return (isinstance(key, bytes) and own in key
            and kernel_sources.callee_sources(m for m, _ in sources) == tuple(sources))


def _mtime(path: Path, missing: int) -> int:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return missing


def module_cached(module: str, qualname: str) -> bool:
    """:func:`cached` for the kernel ``qualname`` of the kernel module named ``module``,
    imported here; False where it does not import (numba missing)."""
    try:
        found = importlib.import_module(module)
    except ImportError:
        return False
    return cached(found.__file__, qualname)


def prepare() -> None:
    """Pay the compiled kernels' load now (a caller that knows they will run): this
    module's run-time pieces, or numba's import where they cannot be set up."""
    if ENABLED and not _numba_settings():
        with _lock:
            rt = _setup()
            if rt is not None and _parts(rt) is not None:
                return
    from mitld_lp.util import numba_narrow
    numba_narrow.import_numba()


class LazyNumba:
    """A module's stand-in for numba (:func:`lazy_numba`)."""

    def __init__(self, module_globals: dict[str, Any]) -> None:
        self.globals = module_globals
        self.kernels: list[Kernel] = []  # the module's, in their order

    def njit(self, *args: Any, **options: Any) -> Any:
        if args and callable(args[0]) and len(args) == 1 and not options:
            return self.njit()(args[0])
        if args:  # explicit signatures: numba's business
            return numba_module().njit(*args, **options)

        def decorate(pyfunc: Any) -> Any:
            with _lock:
                kernel = Kernel(pyfunc, options)
                self.kernels.append(kernel)
                return kernel

        return decorate

    def __getattr__(self, name: str) -> Any:
        return getattr(numba_module(), name)


def numba_module() -> Any:
    """numba, imported as the compiled modules import it (without PyYAML, the narrow load
    of cached kernels, the disk cache's lock); ImportError where numba is missing.  Each
    :class:`Kernel` makes its numba dispatcher when first asked
    (:meth:`Kernel.numba_dispatcher`); the modules' globals keep naming the kernels:
    numba types one as its dispatcher (``_numba_type_``, which numba's ``typeof`` asks of
    any object) and inlines it by its ``targetoptions`` and ``py_func`` (both the
    dispatcher's), so what it compiles is what it compiled with the dispatcher there."""
    with _lock:
        if not _numba:
            from mitld_lp.util import numba_cache, numba_narrow

            _numba.append(numba_narrow.require_numba())
            numba_narrow.install()
            numba_cache.install()
        return _numba[0]


class Kernel:
    """A kernel of a lazy module (module docs): called as numba's dispatcher is."""

    def __init__(self, pyfunc: Any, options: dict[str, Any]) -> None:
        self.py_func = pyfunc
        self.options = options
        self.dispatcher: Any = None
        self.__name__ = pyfunc.__name__
        self.__qualname__ = pyfunc.__qualname__
        self.__module__ = pyfunc.__module__
        self.__doc__ = pyfunc.__doc__
        self.__wrapped__ = pyfunc
        self._calls: dict[tuple, Any] = {}  # type key -> callable, None: numba's

    def __repr__(self) -> str:
        return f"<lazy kernel {self.__module__}.{self.__qualname__}>"

    def __getattr__(self, name: str) -> Any:
        """numba's dispatcher's attributes (``overloads``, ``targetoptions``, and
        ``_numba_type_``, by which numba types a kernel a kernel calls)."""
        if name.startswith("__") or name in ("dispatcher", "py_func", "options"):
            raise AttributeError(name)
        return getattr(self.numba_dispatcher(), name)

    def numba_dispatcher(self) -> Any:
        """numba's dispatcher of this kernel (numba imported, :func:`numba_module`)."""
        if self.dispatcher is None:
            numba = numba_module()
            with _lock:
                if self.dispatcher is None:
                    self.dispatcher = numba.njit(**self.options)(self.py_func)
        return self.dispatcher

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        key = type_key(args) if ENABLED and not kwargs and self.cacheable() else None
        if key is None:
            return self.numba_dispatcher()(*args, **kwargs)
        call = self._calls.get(key, _UNSET)
        if call is _UNSET:
            with _lock:
                call = self._calls.get(key, _UNSET)
                if call is _UNSET:
                    call = _load(self, key)
                    self._calls[key] = call
        if call is not None:
            return call(*args)
        dispatcher = self.numba_dispatcher()
        if (self.__module__, self.__qualname__) in kernel_sources.STALE:
            kernel_sources.flush_numba_cache(self, dispatcher)
        result = dispatcher(*args)
        with _lock:
            if self._calls.get(key) is None:
                _store(self, key, args, dispatcher)
                self._calls[key] = dispatcher
        return result

    def cacheable(self) -> bool:
        return (bool(self.options.get("cache")) and self.py_func.__closure__ is None
                and not self.options.get("parallel"))

    def compile_for(self, args: tuple) -> bool:
        """Make the signature of ``args`` linkable from the cache without running the
        kernel (``mitld-lp warm``): numba's compile (or its cache) and this module's
        cache file, as a call's miss writes them.  False where the loader links it
        already (nothing compiled)."""
        key = type_key(args) if ENABLED and self.cacheable() else None
        with _lock:
            if key is not None and self._calls.get(key, _UNSET) is _UNSET:
                self._calls[key] = _load(self, key)
            if key is not None and self._calls[key] is not None:
                return False
            dispatcher = self.numba_dispatcher()
            if (self.__module__, self.__qualname__) in kernel_sources.STALE:
                kernel_sources.flush_numba_cache(self, dispatcher)
            dispatcher.compile(tuple(dispatcher.typeof_pyval(a) for a in args))
            if key is not None:
                _store(self, key, args, dispatcher)
                self._calls[key] = dispatcher
        return True


_UNSET = object()


# --- the run-time pieces: numba's extension modules, llvmlite's linker ------------------

_EXTENSIONS = (("numba._helperlib", "_helperlib"),
               ("numba.core.runtime._nrt_python", "core/runtime/_nrt_python"),
               ("numba._dynfunc", "_dynfunc"))
_runtime: list[Any] = []  # [_Runtime or None] once set up
_llvm: list[Any] = []  # [(llvmlite.binding, its MCJIT engine) or None] once set up


def _setup() -> _Runtime | None:
    """The run-time pieces, set up once (module docs); None where any is missing."""
    if _runtime:
        return _runtime[0]
    found = None
    try:
        found = _setup_once()
    finally:
        _runtime.append(found)
    return found


class _Runtime:
    """numba's extension modules' pieces, the symbols a kernel's object may name, and
    the cache key's parts (None until known: remembered, or from llvmlite)."""

    def __init__(self, dynfunc: Any, symbols: dict[str, int], probe: Any,
                 machine: tuple | None) -> None:
        self.dynfunc = dynfunc
        self.symbols = symbols
        self.probe = probe
        self.parts = None if machine is None else (sys.version, probe[1], *machine)


def _setup_once() -> _Runtime | None:
    ext = elf_runtime.load_extensions(_EXTENSIONS)
    if ext is None:
        return None
    (helperlib, nrt, dynfunc), numba_id = ext
    if not elf_runtime.prime_unpickle(helperlib.c_helpers["unpickle"]):
        return None
    probe = elf_runtime.probe(sys.version, numba_id)
    return _Runtime(dynfunc, elf_runtime.explicit_symbols(helperlib, nrt, dynfunc),
                    (None, numba_id) if probe is None else probe,
                    elf_runtime.read_machine(probe))


def _parts(rt: _Runtime) -> tuple | None:
    """The cache key's parts of this process (remembered, else llvmlite's)."""
    if rt.parts is None:
        try:
            _setup_llvm(rt)
        except Exception:  # noqa: BLE001 - no llvmlite: no key, numba's calls
            return None
    return rt.parts


def _setup_llvm(rt: _Runtime) -> tuple | None:
    """llvmlite's MCJIT with the symbols numba's load adds, once: (ll, engine)."""
    if _llvm:
        return _llvm[0]
    _llvm.append(None)
    import llvmlite
    from llvmlite import binding as ll

    ll.initialize_native_target()
    ll.initialize_native_asmprinter()
    triple = ll.get_process_triple()
    cpu = ll.get_host_cpu_name()
    try:
        features = ll.get_host_cpu_features().flatten()
    except RuntimeError:
        features = ""
    # the same addresses numba's own load adds, so adding them twice is harmless
    for name, address in rt.symbols.items():
        ll.add_symbol(name, address)
    target = ll.Target.from_triple(triple)
    tm = target.create_target_machine(cpu=cpu, features=features, reloc="static",
                                      codemodel="jitdefault", jit=True)
    engine = ll.create_mcjit_compiler(ll.parse_assembly(""), tm)
    machine = (llvmlite.__version__, tuple(ll.llvm_version_info), (triple, cpu, features))
    parts = (sys.version, rt.probe[1], *machine)
    rt.parts = parts  # llvmlite's word over a remembered one (rewritten just below)
    if rt.probe[0] is not None:
        elf_runtime.write_machine(rt.probe, machine)
    _llvm[0] = (ll, engine)
    return _llvm[0]


def _numba_settings() -> bool:
    """Whether a ``NUMBA_*`` setting other than the cache directory, or a numba config
    file in the working directory, is in force (it may change what numba compiles: the
    loader then leaves every call to numba)."""
    return (any(k.startswith("NUMBA_") and k != "NUMBA_CACHE_DIR" for k in os.environ)
            or os.path.isfile(".numba_config.yaml"))


def _runtime_key(kernel: Kernel, key: tuple, parts: tuple) -> bytes:
    """The key a cache file must carry (module docs)."""
    code = kernel.py_func.__code__
    return repr((kernel_files.FORMAT, parts, kernel.__module__, kernel.__qualname__,
                 kernel_sources.source_hash(code.co_filename),
                 hashlib.sha256(code.co_code).hexdigest(), key)).encode()


def _load(kernel: Kernel, key: tuple) -> Any:
    """The kernel's compiled call for arguments of type ``key`` from the cache, or None
    (module docs); never raises."""
    if _numba_settings():
        return None
    py_file = kernel.py_func.__code__.co_filename
    name = kernel_files.file_name(py_file, kernel.__qualname__, key)
    data = None
    for directory in kernel_files.directories(py_file):
        try:
            data = (directory / name).read_bytes()
            break
        except OSError:
            continue
    if data is None:
        return None
    try:
        return _link(kernel, key, data)
    except Exception:  # noqa: BLE001 - any failure: numba's call, the file rewritten
        return None


def _link(kernel: Kernel, key: tuple, data: bytes) -> Any:
    found = kernel_files.unpack(data)
    if found is None:
        return None
    meta, object_code = found
    rt = _setup()
    parts = None if rt is None else _parts(rt)
    if rt is None or parts is None:
        return None
    if meta.get("key") != _runtime_key(kernel, key, parts):
        return None
    sources = meta.get("sources", ())
    if kernel_sources.callee_sources(m for m, _ in sources) != sources:
        # a kernel of another module compiled into it has changed; numba's own cache
        # checks the kernel's own file only, so its entry is as stale: flushed before
        # numba's call (Kernel.__call__), which then compiles afresh
        kernel_sources.STALE.add((kernel.__module__, kernel.__qualname__))
        return None
    module = sys.modules.get(kernel.__module__)
    if module is None:
        return None
    digest = (hashlib.sha256(object_code).digest(), meta["wrapper"])
    if digest in _linked:  # an object is linked once a process (its symbols are global)
        return _linked[digest]
    envs = []
    for env_name, modname, consts in meta["envs"]:
        if modname == kernel.__module__:
            scope = module.__dict__
        elif modname in sys.modules and modname.startswith("mitld_lp."):
            scope = sys.modules[modname].__dict__
        else:  # a numba helper's (no constants: the writer refuses others) or a module
            # not imported: nopython code never reads an environment's globals (only
            # object mode's lowering does), as numba_narrow's stand-in has it
            scope = {"__name__": modname}
        env = rt.dynfunc.Environment(scope)
        env.consts.extend(np.dtype(c) for c in consts)
        envs.append((env_name, env))
    linked = _link_elf(object_code, rt) if LINKER == "elf" else None
    if linked is None:
        linked = _link_llvm(object_code, meta, rt)
        if linked is None:
            return None
    address, keep = linked
    import ctypes

    for env_name, env in envs:
        at = address(env_name, False)
        if not at:
            return None
        ctypes.c_void_p.from_address(at).value = id(env)
    wrapper = address(meta["wrapper"], True)
    own = dict(envs)[meta["env"]]
    if not wrapper:
        return None
    call = rt.dynfunc.make_function(module, kernel.__name__,
                                    f"compiled wrapper for {kernel.__qualname__!r}",
                                    wrapper, own, (keep, tuple(e for _, e in envs)))
    _loaded[0] += 1
    _loaded[1] += keep is not _llvm
    _linked[digest] = call
    return call


def _link_elf(object_code: bytes, rt: _Runtime) -> tuple | None:
    """The object linked by :mod:`mitld_lp.util.elf_link`: (address of a symbol, what
    keeps it), or None where it refuses."""
    if not elf_link.supported():
        return None
    if rt.__dict__.get("resolve") is None:
        rt.resolve = elf_runtime.resolver(rt.symbols)
    try:
        linked = elf_link.link(object_code, rt.resolve)
    except elf_link.Refused:
        return None
    return (lambda name, _function: linked.symbols.get(name)), linked


def _link_llvm(object_code: bytes, meta: dict, rt: _Runtime) -> tuple | None:
    """The object linked by llvmlite's MCJIT, as :func:`_link_elf`."""
    found = _setup_llvm(rt)
    if found is None:
        return None
    ll, engine = found
    if any(ll.address_of_symbol(s) is None for s in meta["undefined"]):
        return None  # LLVM's linker would abort the process on it
    engine.add_object_file(ll.ObjectFileRef.from_data(object_code))
    engine.finalize_object()

    def address(name: str, function: bool) -> int:
        if function:
            return engine.get_function_address(name)
        return engine.get_global_value_address(name)

    return address, _llvm


# --- writing a cache file from numba's own cache entry ---------------------------------


def _store(kernel: Kernel, key: tuple, args: tuple, dispatcher: Any) -> None:
    """Write the cache file of ``key`` from numba's cache entry of the signature numba
    gave these arguments; nothing where anything is not as expected (never raises)."""
    if _numba_settings():
        return
    try:
        _store_entry(kernel, key, args, dispatcher)
    except Exception:  # noqa: BLE001 - the cache is an optimisation; numba's call stands
        return


def _store_entry(kernel: Kernel, key: tuple, args: tuple, dispatcher: Any) -> None:
    sig = tuple(dispatcher.typeof_pyval(a) for a in args)
    cres = dispatcher.overloads.get(sig)
    cache = getattr(dispatcher, "_cache", None)
    if cres is None or cache is None or not hasattr(cache, "_cache_file"):
        return
    rt = _setup()
    parts = None if rt is None else _parts(rt)
    if parts is None:
        return
    codegen = cres.target_context.codegen()
    if tuple(codegen.magic_tuple()) != parts[-1]:
        return  # numba compiled for another CPU description than the loader would key
    from mitld_lp.util import numba_cache

    with numba_cache.locked(cache._cache_path):
        data = cache._cache_file.load(cache._index_key(sig, codegen))
    if data is None:
        return
    libdata, fndesc, env, signature, objectmode, lifted, _ann, reload_init, refs = data
    name, kind, payload = libdata
    if (kind != "object" or objectmode or lifted or reload_init
            or tuple(signature.args) != sig):
        return
    object_code = payload[0]
    undefined = kernel_files.undefined_symbols(object_code)
    if undefined is None or any(s.startswith(".numba.unresolved$") for s in undefined):
        return
    envs = []
    for e in [env, *refs]:
        modname = e.globals.get("__name__")
        consts = list(e.consts)
        if not isinstance(modname, str) or not all(
                isinstance(c, np.dtype) and c.fields is None and c.kind in "biufc"
                for c in consts):
            return
        if consts and not modname.startswith("mitld_lp."):
            return
        if not modname.startswith(("mitld_lp.", "numba.")):
            return
        envs.append((e.env_name, modname, tuple(c.str for c in consts)))
    envs = list(dict.fromkeys(envs))  # each once, in order (names unique: the same list)
    callees = kernel_sources.kernel_modules(kernel.__module__) | {  # inlined ones: no env
        m for _, m, _ in envs if m.startswith("mitld_lp.") and m != kernel.__module__}
    sources = kernel_sources.callee_sources(callees)
    if callees and not sources:
        return
    meta = {"key": _runtime_key(kernel, key, parts),
            "wrapper": fndesc.llvm_cpython_wrapper_name, "env": fndesc.env_name,
            "envs": tuple(envs), "undefined": tuple(sorted(undefined)), "sources": sources}
    name = kernel_files.file_name(kernel.py_func.__code__.co_filename, kernel.__qualname__, key)
    kernel_files.write(Path(cache._cache_path) / name,
                       kernel_files.pack(marshal.dumps(meta), object_code))


