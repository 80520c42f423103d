"""A program importing the package: the package's start-up costs cut where nobody sees it.

The command line's start-up (:func:`mitld_lp.startup.lean_start`) changes what the
whole process imports and how every dataclass is made.  A program that imports the
package (a notebook, a benchmark's worker timing ``load_model`` and ``synthesize``, a
service) may ask for three cuts that change nothing it can use, by calling
:func:`install` before its own heavy imports; each is made when its module is first
imported.  ``import mitld_lp`` alone installs none of this hook; it makes the three
cuts only for what the package itself imports, while its modules import
(:mod:`mitld_lp.own_imports`, the collector held too: the third when the package's own
code imports csgraph or ``scipy.sparse.linalg``), and the hook makes them for the
program's own imports too (``import mitld_lp`` stays free of NumPy and ``dataclasses``:
:mod:`mitld_lp.runtime` imports NumPy alone):

* SciPy's array-API layer (``scipy._lib.array_api_compat.numpy``, which every
  ``scipy.sparse`` import loads) copies NumPy's namespace without importing
  ``numpy.f2py``, ``numpy.testing``, ``numpy.ma``, ``numpy.polynomial``... which the copy
  hands over from NumPy when first asked (:func:`mitld_lp.startup.lean_scipy`, the
  same two halves): 0.1 s of CPU on a PRISM route.  The copy lists the same names, each
  NumPy's own object; NumPy's ``__all__`` and ``dir`` are put back at once.  Nothing if
  SciPy's layer was imported before the package.
* The package's own dataclasses get their comparison, hash, representation and frozen
  methods as closures and their ``__init__`` from the table of compiled code
  (:mod:`mitld_lp.dataclass_closures`, :mod:`mitld_lp.init_cache`,
  both with ``package_only``): 0.1 s on a PRISM route.  Every other module's dataclasses
  are made by the stdlib as before.
* ``scipy.sparse.csgraph`` is imported without ``scipy.sparse.linalg``'s ``__init__``
  and so without ``scipy.linalg`` (LAPACK and BLAS wrappers, whose OpenBLAS starts its
  threads): csgraph's searches need neither, and ``scipy.sparse.linalg`` loads whole at
  the first name read other than ``LinearOperator`` and the direct solvers (``splu``,
  ``spsolve``..., served from their own module with ``scipy.linalg`` left for later
  too, :func:`mitld_lp.own_imports.linalg_later`) (:func:`sparse_linalg_later`):
  0.05-0.11 s of CPU on a PRISM route, which walks graphs and factorises with ``splu``
  alone.  The command line's start keeps this one (:func:`install` with ``command``).

The hook is a finder at the front of ``sys.meta_path`` that answers for those modules
only, once each (the module's own finder finds it; the loader is wrapped for the one
import, then put back on the module), and leaves ``sys.meta_path`` when all were
seen.  Nothing changes an answer: the same objects, the same methods.
"""

from __future__ import annotations

import sys

from mitld_lp.own_imports import (  # the halves, named here too (startup, tests)
    NUMPY_EXTRAS,
    SCIPY_NUMPY_COPY,
    SPARSE_LINALG,
    body_later,
    hand_over_extras,
    numpy_listed_without_extras,
    scipy_copy_around,
    spec_around,
)

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from importlib.machinery import ModuleSpec
    from types import ModuleType
    from typing import Any

__all__ = ["NUMPY_EXTRAS", "SCIPY_NUMPY_COPY", "install", "remove", "installed", "waiting_for",
           "sparse_linalg_later", "lark_without_regex", "numpy_listed_without_extras",
           "hand_over_extras"]


def _dataclasses_around() -> Callable[[ModuleType | None], None]:
    """Nothing before ``dataclasses`` runs; after it, the package's makers."""

    def after(module: ModuleType | None) -> None:
        if module is not None:
            _dataclasses_cut()

    return after


def _dataclasses_cut() -> None:
    from mitld_lp import init_cache
    from mitld_lp.dataclass_closures import methods_without_exec

    methods_without_exec(package_only=True)
    init_cache.install(package_only=True)


def sparse_linalg_later() -> Callable[[ModuleType | None], None]:
    """Before ``scipy.sparse.csgraph`` runs: ``scipy.sparse.linalg`` in ``sys.modules`` as
    a :class:`mitld_lp.own_imports.BodyLater`, which csgraph's ``_laplacian`` takes its
    one name from (``LinearOperator``, for ``laplacian(form="lo")``).  csgraph's
    searches need none of it; its ``__init__`` imports ``scipy.linalg`` (LAPACK, BLAS,
    decompositions): 0.11 s of CPU on a PRISM route that only walks graphs.  The direct
    solvers (``splu``, ``spsolve``...) are served from their own module with
    ``scipy.linalg`` left for later too; the first other name read loads it whole.
    Nothing if it is imported already."""
    body_later(SPARSE_LINALG)
    return lambda csgraph: None


def lark_without_regex() -> Callable[[ModuleType | None], None]:
    """Before lark runs: ``import regex`` fails, as where the ``regex`` package is not
    installed (it is not one of lark's requirements): lark imports it at once when it
    can, for grammars that ask for it (``Lark(regex=True)``, Unicode categories), which
    the formula grammar does not; its import is 0.012 s of CPU.  After lark's body,
    ``regex`` imports for whoever asks, as usual.  The command line's start waits for
    lark so (a solve whose formula the plain parser reads never imports lark: the
    start no longer imports it to cut ``regex``); nothing if ``regex`` is imported."""
    if "regex" in sys.modules:
        return lambda lark: None
    sys.modules["regex"] = None  # type: ignore[assignment]  # ``import regex`` fails

    def after(lark: ModuleType | None) -> None:
        if "regex" in sys.modules and sys.modules["regex"] is None:
            del sys.modules["regex"]

    return after


class _Hook:
    """The finder: the modules it waits for, and what runs around each one's import."""

    def __init__(self) -> None:
        self.waiting: dict[str, Any] = {}  # name -> what runs around its import

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        around = self.waiting.pop(name, None)
        if around is None:
            return None
        if not self.waiting:
            remove()
        return spec_around(self, name, path, target, around)


_hook: _Hook | None = None


def install(command: bool = False) -> None:
    """Put the hook in place (a program asks for it; ``command``: the command line's
    :func:`mitld_lp.startup.lean_start` does, with its own wider cuts, so the hook waits
    for csgraph, and for lark to import it without ``regex``,
    :func:`lark_without_regex`): each cut now if its module is imported already, else
    when it is."""
    global _hook
    remove()
    hook = _Hook()
    if not command:
        if "dataclasses" in sys.modules:
            _dataclasses_cut()
        else:
            hook.waiting["dataclasses"] = _dataclasses_around
        if SCIPY_NUMPY_COPY not in sys.modules:
            hook.waiting[SCIPY_NUMPY_COPY] = scipy_copy_around
    if "scipy.sparse.csgraph" not in sys.modules:
        hook.waiting["scipy.sparse.csgraph"] = sparse_linalg_later
    if command and "lark" not in sys.modules and "regex" not in sys.modules:
        hook.waiting["lark"] = lark_without_regex
    if hook.waiting:
        _hook = hook
        sys.meta_path.insert(0, hook)


def remove() -> None:
    """Take the hook out of ``sys.meta_path`` (what it has done stays)."""
    global _hook
    if _hook is not None:
        try:
            sys.meta_path.remove(_hook)
        except ValueError:
            pass
        _hook = None


def installed() -> bool:
    """Whether the hook is waiting for a module."""
    return _hook is not None


def waiting_for() -> list[str]:
    """The modules whose import the hook still waits for."""
    return sorted(_hook.waiting) if _hook is not None else []
