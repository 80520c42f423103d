"""NumPy's and SciPy's OpenBLAS thread pools made to sleep as soon as they are idle,
when a program importing the package loads them.

Each of NumPy's and SciPy's wheels bundles an OpenBLAS, and each starts a pool of one
thread per core when its library is loaded (SciPy's when its first extension using
BLAS is: ``scipy.linalg``, the direct sparse solvers).  A thread of the pool waits for
work by spinning for ``2**OPENBLAS_THREAD_TIMEOUT`` cycles (default ``2**28``, about
0.1 s) before it sleeps, and it spins so right after it is started: on a 2-core machine
0.040-0.045 s of CPU for NumPy's pool and 0.020-0.025 s for SciPy's, paid by a process
that never calls dense BLAS on operands large enough to be threaded (the package's
solvers are sparse).  The command line asks for one thread
(:data:`mitld_lp.startup.BLAS_THREADS`); a program importing the package keeps its
pools, and this module only asks them to sleep when idle: ``OPENBLAS_THREAD_TIMEOUT=4``
(OpenBLAS's least, ``2**4`` cycles) while the library is loaded, in the environment
only for the ``dlopen`` of an extension module of NumPy or SciPy (its
``create_module``), and the environment as it was after.  The pools keep their
threads: a large product still runs on every core; a call after an idle spell wakes
them (a futex) instead of finding them spinning.

Nothing is set when the environment already says anything about OpenBLAS's threads
(:data:`USER_SETTINGS`: the user's, or the command line's one thread), nor for a library
already loaded (NumPy imported before the package: its pool is as NumPy made it).
:func:`install` puts the finder in ``sys.meta_path`` (the package's import window,
:func:`mitld_lp.own_imports.install`, does; ``MITLD_LP_PLAIN_IMPORTS=1`` leaves both
out).  The setting is made only while the process runs one Python thread: the C
library's environment is not safe to change while another thread may read it; where
another runs, the pools are left as the libraries make them.
"""

from __future__ import annotations

import os
import sys
import threading

TYPE_CHECKING = False
if TYPE_CHECKING:
    from importlib.machinery import ModuleSpec
    from types import ModuleType
    from typing import Any

__all__ = ["TIMEOUT", "SETTING", "USER_SETTINGS", "PACKAGES", "IdleLoader", "install",
           "installed", "uninstall", "wanted"]

SETTING = "OPENBLAS_THREAD_TIMEOUT"
TIMEOUT = "4"
"""OpenBLAS's least thread timeout: an idle thread spins ``2**4`` cycles, then sleeps."""

USER_SETTINGS = ("OPENBLAS_THREAD_TIMEOUT", "GOTO_THREAD_TIMEOUT", "OPENBLAS_NUM_THREADS",
                 "GOTO_NUM_THREADS", "OMP_NUM_THREADS")
"""Environment variables any of which, set, leaves OpenBLAS as the environment says."""

PACKAGES = ("numpy.", "scipy.")
"""The packages whose wheels bundle an OpenBLAS loaded by their extension modules."""

_lock = threading.Lock()  # the count below and the finder; never held across a load
_loading = 0  # extension modules being created with the setting made (nested, or threads)
_finder: _Finder | None = None


def wanted(environ: Any = None) -> bool:
    """Whether the setting is made: the environment says nothing of OpenBLAS's threads."""
    env = os.environ if environ is None else environ
    return not any(name in env for name in USER_SETTINGS)


class IdleLoader:
    """An extension module's own loader whose ``create_module`` (the ``dlopen``, which
    loads the OpenBLAS it links and starts its pool) runs with :data:`SETTING` at
    :data:`TIMEOUT`, the environment put back after; every other attribute is the
    loader's own, and the module keeps its own loader."""

    def __init__(self, loader: Any) -> None:
        self._loader = loader

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        global _loading
        spec.loader = self._loader  # the module's own loader, as without the finder
        with _lock:  # (a module's init may import others: the setting made once)
            made = _loading > 0 or (wanted() and threading.active_count() == 1)
            if made:
                _loading += 1
                os.environ[SETTING] = TIMEOUT
        if not made:
            return self._loader.create_module(spec)  # type: ignore[no-any-return]
        try:
            return self._loader.create_module(spec)  # type: ignore[no-any-return]
        finally:
            with _lock:
                _loading -= 1
                if _loading == 0:
                    os.environ.pop(SETTING, None)

    def exec_module(self, module: ModuleType) -> None:
        module.__loader__ = self._loader
        self._loader.exec_module(module)


class _Finder:
    """Finds nothing itself: an extension module of :data:`PACKAGES`, as the finders
    after it find it, gets an :class:`IdleLoader` for its one import."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        if not name.startswith(PACKAGES) or not wanted():
            return None
        finders = sys.meta_path
        after = finders.index(self) + 1 if self in finders else 0
        for finder in finders[after:]:
            if not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is None:
                continue
            origin = spec.origin or ""
            if (spec.loader is not None and hasattr(spec.loader, "create_module")
                    and origin.endswith((".so", ".pyd")) and not isinstance(
                        spec.loader, IdleLoader)):
                spec.loader = IdleLoader(spec.loader)
            return spec
        return None


def install(after: object = None) -> None:
    """Put the finder in ``sys.meta_path`` (once): right after ``after`` where that is
    there (the finders before it answer first), else at the front."""
    global _finder
    with _lock:
        if _finder is None:
            _finder = _Finder()
            finders = sys.meta_path
            finders.insert(finders.index(after) + 1 if after in finders else 0, _finder)


def installed() -> bool:
    """Whether the finder is in place."""
    return _finder is not None and _finder in sys.meta_path


def uninstall() -> None:
    """Take the finder out (a test putting back the state it found)."""
    global _finder
    with _lock:
        if _finder is not None:
            try:
                sys.meta_path.remove(_finder)
            except ValueError:
                pass
            _finder = None
