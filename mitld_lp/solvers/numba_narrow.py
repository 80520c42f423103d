"""numba's cached kernels loaded without the CPU target's whole registry.

Before numba loads a kernel from its disk cache it refreshes the CPU target's context
(``numba.core.caching.Cache.load_overload``), and the refresh's first step,
``CPUContext.load_additional_registries``, imports some 60 of numba's modules (NumPy's
linear algebra, random generators and polynomials, typed lists, dicts and sets,
``jitclass``, datetimes...) and installs their implementations: 0.35 s of CPU a process
(``experiments/numba_load.py``), which only *compiling* a function needs.  A cached
kernel is machine code already; the one thing of that step it needs is numba's runtime
(``rtsys.initialize``, for the arrays the kernel allocates).

:func:`install` has that step do only the runtime while a kernel is being loaded from the
cache; everywhere else (compiling a kernel on a cache miss, which refreshes the context
again first, and any other use) it does the whole of it, and the registries still missing
are installed then (numba's refresh installs whatever its registries have gained).  The
kernel that runs is the same cached machine code either way: results are the same to the
bit (``tests/test_startup_lazy.py``).  On a numba whose version or internals are not the
ones checked here nothing is changed.

Every module of compiled kernels (:mod:`~mitld_lp.solvers.compiled_kernels`,
:mod:`~mitld_lp.solvers.level_kernels`, :mod:`~mitld_lp.solvers.compiled_graph`,
:mod:`~mitld_lp.solvers.compiled_elimination`, :mod:`mitld_lp.sensing.kernels`,
:mod:`mitld_lp.sensing.group_kernels`) calls :func:`install` right after ``import numba``,
so whichever kernel a process asks for first is loaded narrowly.  :data:`ENABLED` set to
False before the first of them is imported keeps numba's whole load (to measure it).
"""

from __future__ import annotations

import threading
from typing import Any

__all__ = ["ENABLED", "TESTED_NUMBA", "install", "installed"]

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
    except ImportError:
        return False
    if ".".join(numba.__version__.split(".")[:2]) not in TESTED_NUMBA:
        return False
    full = getattr(cpu.CPUContext, "load_additional_registries", None)
    load = getattr(caching.Cache, "load_overload", None)
    if full is None or load is None or not hasattr(rtsys, "initialize"):
        return False

    def load_additional_registries(self: Any) -> None:
        if getattr(_loading, "active", False):
            rtsys.initialize(self)  # the runtime: what a cached kernel needs of this step
            return
        full(self)

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        outer = getattr(_loading, "active", False)
        _loading.active = True
        try:
            return load(self, sig, target_context)
        finally:
            _loading.active = outer

    cpu.CPUContext.load_additional_registries = load_additional_registries
    caching.Cache.load_overload = load_overload
    _installed = True
    return True
