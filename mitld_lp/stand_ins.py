"""Modules the command line's process imports later, or not at all: stand-ins in
``sys.modules`` put there before NumPy, SciPy and lark are imported.

:func:`mitld_lp.startup.lean_start` calls the three functions here, on the command line
only (a program that imports the package gets every module as it imports itself).
Measured on the bundled case (``mitld-lp solve models/bus_grid.toml``), whose process is
mostly start-up: NumPy's docstrings of its C objects 0.014 s of CPU, SciPy's test runner
(with ``subprocess``) about 0.006 s, and the standard modules of :data:`LATER_MODULES`
about 0.01 s, together about 6 % of the process.  No answer, check or message of a
command changes: what is left out is documentation, a test runner and modules whose
functions no command calls, and each of the latter is imported, as it was, the moment
one of its names is read.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types
from typing import Any

__all__ = ["LATER_MODULES", "NUMPY_DOC_MODULES", "SCIPY_TESTS", "later", "modules_when_used",
           "numpy_docs_left_out", "scipy_tests_when_used"]

#: Standard-library modules that NumPy, SciPy, lark and the package's file writers import
#: at their start and use only inside functions that no solve calls, measured on the
#: bundled case (:func:`modules_when_used`): NumPy's ``platform`` (for ``show_runtime``)
#: and ``pickle`` (for ``ndarray.dump``), SciPy's ``pydoc`` (with ``sysconfig``: for
#: reading docstrings), lark's ``tempfile``, ``getpass``, ``pkgutil`` and ``hashlib``
#: (for its grammar cache and grammar files; ``hashlib`` starts OpenSSL), ``zipfile`` and
#: ``csv`` (the package's archive and table writers) and ``subprocess``.
LATER_MODULES = ("platform", "pickle", "pydoc", "tempfile", "getpass", "pkgutil", "hashlib",
                 "zipfile", "csv", "subprocess")

#: NumPy's modules that only attach docstrings (and text signatures) to the objects its
#: C extensions define (:func:`numpy_docs_left_out`).
NUMPY_DOC_MODULES = ("numpy._core._add_newdocs", "numpy._core._add_newdocs_scalars")

#: SciPy's test-runner module, which every SciPy package imports for its ``test()``.
SCIPY_TESTS = "scipy._lib._testutils"


class _Later(types.ModuleType):
    """A module imported when one of its names is first read (:func:`modules_when_used`).

    Its dunder names are its own (``__name__``, a ``__spec__`` of None: the import system
    reads them without importing it) but a package's ``__path__``, and so are the names
    given as ``kept``;
    any other name is the real module's: reading, writing or deleting one imports the
    real module (which then replaces the stand-in in ``sys.modules``) and acts on it, so
    the module's state (``tempfile.tempdir``) is one."""

    def __init__(self, name: str, kept: dict[str, Any] | None = None) -> None:
        super().__init__(name, f"{name}, imported when first used "
                               "(mitld_lp.stand_ins, the command line).")
        vars(self).update(kept or {})

    def _real(self) -> Any:
        real = vars(self).get("_module")
        if real is None:
            name = vars(self)["__name__"]
            if sys.modules.get(name) is self:
                del sys.modules[name]
            real = importlib.import_module(name)
            vars(self)["_module"] = real
        return real

    def __getattr__(self, name: str) -> Any:
        # a package's ``__path__`` is the real one's: importing a submodule of a package
        # put off (``zipfile._path`` on Python 3.12) reads it, and imports the package
        # first; a module's has none (``from m import x`` asks, and must not import it)
        if name == "__path__" and vars(self).get("_package"):
            return self._real().__path__
        if name.startswith("__") and name.endswith("__"):
            raise AttributeError(name)
        return getattr(self._real(), name)

    def __setattr__(self, name: str, value: object) -> None:
        setattr(self._real(), name, value)

    def __delattr__(self, name: str) -> None:
        delattr(self._real(), name)

    def __dir__(self) -> list[str]:
        return dir(self._real())


def later(name: str) -> types.ModuleType:
    """A stand-in for the module ``name`` (found, not imported yet) that imports it when
    one of its names is first read (:class:`_Later`); the caller decides where it goes
    (:func:`modules_when_used` puts it in ``sys.modules``; :mod:`mitld_lp.own_imports`
    hands ``regex`` to lark alone)."""
    spec = importlib.util.find_spec(name)
    return _Later(name, {"_package": spec is not None
                         and spec.submodule_search_locations is not None})


def modules_when_used() -> None:
    """Have each module of :data:`LATER_MODULES` not imported yet imported when one of its
    names is first read, not when a module imports it.

    Python's own :class:`importlib.util.LazyLoader` cannot do this here: on 3.11 and
    3.12 every later ``import`` statement of the module reads its ``__spec__``, which
    runs it.  Instead ``sys.modules`` holds a stand-in (:class:`_Later`) until then:
    ``import platform`` binds it, ``platform.system()`` imports the real module and
    calls it; ``from pickle import Pickler`` imports it at once.  A module that cannot
    be found is left alone (its importer's own ``ImportError`` stays where it was)."""
    for name in LATER_MODULES:
        spec = None if name in sys.modules else importlib.util.find_spec(name)
        if spec is not None:
            sys.modules[name] = _Later(name, {
                "_package": spec.submodule_search_locations is not None})


def numpy_docs_left_out() -> None:
    """Import NumPy without the two modules that write the docstrings of its C objects
    (:data:`NUMPY_DOC_MODULES`): 0.014 s of CPU, about 3 % of the bundled case's
    process, spent on text no command reads.

    ``numpy._core`` imports them for their effect alone: each calls ``add_newdoc`` a few
    hundred times (an import of the place, ``inspect.cleandoc``, a write into the C
    object's documentation slot), and nothing imports a name from them.  Here each is an
    empty module when ``numpy._core`` asks, so NumPy's C functions, types and methods
    keep the documentation compiled into them (mostly none), as under ``python -OO``,
    where NumPy's ``add_docstring`` writes nothing either: a configuration NumPy
    supports.  Only ``help()`` and introspection of those objects (``np.add.__doc__``,
    ``inspect.signature(np.ndarray.sum)``) see the difference.  Nothing when NumPy is
    already imported."""
    if "numpy" in sys.modules:
        return
    for name in NUMPY_DOC_MODULES:
        sys.modules.setdefault(name, types.ModuleType(
            name, "Left out by mitld_lp.stand_ins.numpy_docs_left_out (the command line)."))


def scipy_tests_when_used() -> None:
    """Put off SciPy's test utilities (:data:`SCIPY_TESTS`) until they are used.

    Every SciPy package ends its ``__init__`` with ``test = PytestTester(__name__)``
    (``scipy.sparse.test()`` runs SciPy's own tests of the package), so the first
    ``import scipy`` imports the module defining ``PytestTester``, and with it
    ``subprocess``, ``sysconfig`` and the configuration of the Python build.  Here the
    module is a stand-in (:class:`_Later`) whose ``PytestTester`` keeps the package's
    name; calling it (running the tests) imports the real module and calls the real
    tester, and any other name read imports the real module.  Nothing when SciPy is
    already imported."""
    if "scipy" in sys.modules or SCIPY_TESTS in sys.modules:
        return

    class PytestTester:
        """SciPy's test runner for one package, imported when it runs."""

        def __init__(self, module_name: str) -> None:
            self.module_name = module_name

        def __call__(self, *args: Any, **kwargs: Any) -> Any:
            return stand_in._real().PytestTester(self.module_name)(*args, **kwargs)

    stand_in = _Later(SCIPY_TESTS, {"PytestTester": PytestTester})
    sys.modules[SCIPY_TESTS] = stand_in
