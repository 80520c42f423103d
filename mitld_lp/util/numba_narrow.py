"""numba's cached kernels loaded without the CPU target's whole registry.

Before numba loads a kernel from its disk cache it refreshes the CPU target's context
(``numba.core.caching.Cache.load_overload``), and the refresh's first step,
``CPUContext.load_additional_registries``, imports some 60 of numba's modules (NumPy's
linear algebra, random generators and polynomials, typed lists, dicts and sets,
``jitclass``, datetimes...) and installs their implementations: 0.35 s of CPU a process
(``experiments/numba_load.py``), which only *compiling* a function needs.  A cached
kernel is machine code already; the one thing of that step it needs is numba's runtime
(``rtsys.initialize``, for the arrays the kernel allocates), and even that is read as
machine code from a cache of its own where the cache is this process's
(:mod:`mitld_lp.util.nrt_cache`: 0.042 -> 0.011 s, 29 -> 10 MB).  The same refresh then
refreshes the *typing* context: its additional registries (``cffi_utils``, whose
``cffi.FFI()`` imports cffi's C parser, pycparser and its lexer, and the maths, list,
set and dict declarations) and its builtins, 0.044 + 0.005 s a process, which only the
typing of a function being compiled reads; numba's compiler refreshes both contexts
itself before it compiles (``numba.core.compiler.compile_extra``), so a cache miss
installs them then.  What a cached kernel's first call still pays, measured with
NumPy and SciPy loaded (``experiments/numba_load.py``'s parts, 2026-11-30): numba's
runtime 0.036 s (its functions compiled by LLVM), ``numba.np.arrayobj`` 0.05 s (imported
by the pickled environment of the array helpers inlined in the kernels: its globals are
that module's), and the cache's read and link.  Since the numba-load branch the first two
are cut as well: the runtime's machine code is read from its own cache
(:mod:`mitld_lp.util.nrt_cache`) and the array helpers' environments get a stand-in
for the globals their nopython code never reads (:func:`_rebuild_env`): a
graph kernel's first call 0.144 -> 0.050 s of CPU and 39 -> 16 MB resident.

:func:`install` has that step do only the runtime while a kernel is being loaded from the
cache; everywhere else (compiling a kernel on a cache miss, which refreshes the context
again first, and any other use) it does the whole of it, and the registries still missing
are installed then (numba's refresh installs whatever its registries have gained).  The
kernel that runs is the same cached machine code either way: results are the same to the
bit (``tests/test_startup_lazy.py``).  On a numba whose version or internals are not the
ones checked here nothing is changed.

Every module of compiled kernels (:mod:`~mitld_lp.solvers.compiled_elimination`,
:mod:`mitld_lp.sensing.kernels`, :mod:`mitld_lp.sensing.group_kernels`) calls
:func:`install` right after ``import numba``, and the kernel loader
(:mod:`mitld_lp.util.kernel_loader`, which runs the kernels of
:mod:`~mitld_lp.solvers.compiled_kernels`, :mod:`~mitld_lp.solvers.level_kernels` and
:mod:`~mitld_lp.solvers.compiled_graph` without numba where its cache holds them) calls it
when it imports numba at a miss, so whichever kernel a process asks numba for first is
loaded narrowly.  :data:`ENABLED` set to
False before the first of them is imported keeps numba's whole load (to measure it).
:func:`import_numba` imports numba without PyYAML (the sweeps and the analysis call it
before their first kernel); while it runs, ``import yaml`` in another thread of the
process would fail, as it would without PyYAML installed.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import threading
import weakref
from typing import Any

__all__ = ["ENABLED", "TESTED_NUMBA", "import_numba", "install", "installed"]

ENABLED = True
"""Whether :func:`install` puts the narrow load in place (False: numba's whole load)."""

#: numba's versions (major.minor) whose loading path this was written and checked for.
TESTED_NUMBA = ("0.68",)

_loading = threading.local()  # set while a kernel is being loaded from the disk cache
_installed = False


def installed() -> bool:
    """Whether the narrow load is in place in this process."""
    return _installed


def install() -> bool:
    """Put the narrow load in place (imports numba); False, nothing changed, where numba
    is missing, of an untested version, or not as expected, or :data:`ENABLED` is
    False."""
    global _installed
    if _installed:
        return True
    if not ENABLED:
        return False
    try:
        import numba
        from numba.core import caching, cpu
        from numba.core.runtime import rtsys
        from numba.core.typing import context as typing_context
    except ImportError:
        return False
    if ".".join(numba.__version__.split(".")[:2]) not in TESTED_NUMBA:
        return False
    full = getattr(cpu.CPUContext, "load_additional_registries", None)
    load = getattr(caching.Cache, "load_overload", None)
    typing_class = getattr(typing_context, "Context", None)
    typing_full = getattr(typing_class, "refresh", None)
    if (full is None or load is None or typing_full is None
            or not hasattr(rtsys, "initialize") or not hasattr(rtsys, "_init")):
        return False
    from mitld_lp.util import nrt_cache
    def load_additional_registries(self: Any) -> None:
        if getattr(_loading, "active", False):
            # the runtime: what a cached kernel needs of this step, its module's machine
            # code itself from a cache where it is this process's (nrt_cache)
            nrt_cache.initialize(self)
            return
        full(self)

    def typing_refresh(self: Any) -> None:
        if getattr(_loading, "active", False):
            return  # typing is for compiling; a compile refreshes it first (module docs)
        typing_full(self)

    from numba.core import environment

    rebuild = getattr(environment, "_rebuild_env", None)
    env_class = getattr(environment, "Environment", None)
    stand_in = (rebuild is not None and isinstance(getattr(env_class, "_memo", None),
                                                   weakref.WeakValueDictionary))
    _numba_env[:] = [rebuild, env_class]

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        outer = getattr(_loading, "active", False)
        _loading.active = True
        swap = stand_in and not outer
        if swap:  # the data file's unpickling looks the rebuild up by name (at its call)
            environment._rebuild_env = _rebuild_env
        try:
            return load(self, sig, target_context)
        finally:
            _loading.active = outer
            if swap:
                environment._rebuild_env = rebuild

    cpu.CPUContext.load_additional_registries = load_additional_registries
    typing_class.refresh = typing_refresh
    caching.Cache.load_overload = load_overload
    _installed = True
    return True


ENV_STAND_IN = frozenset({"numba.np.arrayobj"})
"""Modules whose globals a cached kernel's array helpers' environments name but whose
code never reads them (:func:`_rebuild_env`)."""


_numba_env: list[Any] = []  # numba's _rebuild_env and Environment, once installed


def _rebuild_env(modname: str, consts: Any, env_name: str) -> Any:
    """numba's ``environment._rebuild_env`` while :func:`install`'s load of a cached
    kernel runs (put in place for that call only, under numba's compiler lock; numba's
    own everywhere else, so that nothing it pickles names this function).

    A cached kernel's entry names the environment of every helper linked into it, by
    its module's name, constants and symbol; numba rebuilds each by importing that module
    for its ``globals``.  The array helpers (``np.empty``, ``np.zeros``, ``np.full``... of
    ``numba.np.arrayobj``) are nopython code: only object-mode lowering reads an
    environment's globals (``pylowering``), and their constants are empty (nothing a
    helper's machine code could read).  Importing ``numba.np.arrayobj`` for them (it
    imports numba's unicode, hashing and character sequences) was 0.05 s of CPU and 3 MB
    a process.  Such an environment (a module of :data:`ENV_STAND_IN` not imported yet,
    no constants, in the thread that loads) gets a globals dict holding only the module's
    ``__name__`` (what numba's ``__reduce__`` and ``can_cache`` read of it), kept in
    numba's memo as numba keeps its own.  Anything else is numba's rebuild, unchanged; a
    compile imports the module as before (its registries)."""
    rebuild, env_class = _numba_env
    if (getattr(_loading, "active", False) and len(consts) == 0
            and modname in ENV_STAND_IN and modname not in sys.modules):
        env = env_class._memo.get(env_name)
        if env is None:
            env = env_class({"__name__": modname})
            env.env_name = env_name
            env_class._memo[env_name] = env
        return env
    return rebuild(modname, consts, env_name)


class _LazyYaml:
    """PyYAML for ``numba.core.config``, imported at its first use: numba reads a
    ``.numba_config.yaml`` of the working directory with it, if there is one, when it
    compiles (``config.reload_config``)."""

    def __getattr__(self, name: str) -> Any:
        import yaml

        return getattr(yaml, name)


def require_numba() -> Any:
    """:func:`import_numba` for a compiled module, which cannot work without numba: the
    module, or ImportError where numba is missing (its importers fall back on that)."""
    numba = import_numba()
    if numba is None:
        raise ImportError("numba is not installed")
    return numba


def import_numba() -> Any:
    """``import numba`` (the module, or None where it is missing) without importing
    PyYAML with it: ``numba.core.config`` imports it at numba's import (0.024 s of CPU)
    only to read a ``.numba_config.yaml`` of the working directory.  Where there is no
    such file and PyYAML is not loaded yet, numba is imported with ``yaml`` marked
    missing, and its config then given PyYAML imported lazily (:class:`_LazyYaml`), so a
    config file that appears later is read as numba would (its ``reload_config`` before
    each compile).  numba itself is not changed, and neither is any kernel.  Every
    compiled module imports numba; where one of them imports it first, PyYAML comes
    with it as before (nothing else differs)."""
    if "numba" in sys.modules:
        return sys.modules["numba"]
    hide = ("yaml" not in sys.modules and not os.path.isfile(".numba_config.yaml")
            and importlib.util.find_spec("yaml") is not None)
    if hide:
        sys.modules["yaml"] = None  # type: ignore[assignment]  # import yaml: ImportError
    try:
        import numba
    except ImportError:
        return None
    finally:
        if hide and "yaml" in sys.modules and sys.modules["yaml"] is None:
            del sys.modules["yaml"]
    config = sys.modules.get("numba.core.config")
    if hide and config is not None and not getattr(config, "_HAVE_YAML", True):
        config.yaml = _LazyYaml()
        config._HAVE_YAML = True
    return numba
