"""The package's own imports in a program, made cheaper without touching the program.

A finder at the front of ``sys.meta_path`` answers for the package's modules only
(``mitld_lp.*``; the module's own finder finds it, as without the finder). While such a
module runs its body -- the outermost one, with every import it starts, SciPy's and
lark's included -- and only then:

* Python's cyclic garbage collector is held (``gc.disable``) and put back as the caller
  had it when the body ends, the imports' objects in its oldest generation
  (:func:`mitld_lp.util.collector.release`: nothing frozen, in its reach).  Imports make
  no garbage cycles worth collecting, yet the collector passed over their objects;
* the package's own dataclasses get their comparison, hash, representation and frozen
  methods as closures and their ``__init__`` from the table of compiled code
  (:mod:`mitld_lp.dataclass_closures`, :mod:`mitld_lp.init_cache`, ``package_only``):
  ``dataclasses``'s makers are the package's for the body's time and the stdlib's
  again after it (a class of another module made meanwhile, in another thread, gets the
  stdlib's methods: the makers ask whose class it is);
* SciPy's array-API layer, if the body is what imports it, copies NumPy's namespace
  without importing ``numpy.f2py``, ``numpy.testing``, ``numpy.ma``... which the copy
  hands over from NumPy when first asked (:func:`mitld_lp.startup.lean_scipy`'s two
  halves): the same names, each NumPy's own object, later;
* ``scipy.sparse.linalg``, when the package's code (or csgraph inside the window)
  imports it, is a :class:`BodyLater`: its ``__init__`` (which imports ``scipy.linalg``,
  LAPACK and BLAS: 0.05-0.07 s of CPU) runs when a name other than ``LinearOperator``
  and the direct solvers' (``splu``...) is read; those come from their own modules with
  ``scipy.linalg`` left for later as well (it serves ``LinAlgError``, NumPy's class);
* ``numpy.ma``, imported by NumPy's ``unique`` for the package's code, is a
  :class:`BodyLater` (:mod:`mitld_lp.masked_later`): its body runs at its first use;
* lark, imported by the package, binds stand-ins of ``regex`` and its cache's modules
  (imported when lark first uses them, out of ``sys.modules`` once lark is imported:
  :func:`_lark_around`);
* SciPy's array-API layer, imported by ``scipy._lib._util`` inside the window, is a
  :class:`LayerLater`: its body runs when one of its functions is first called.
* NumPy's and SciPy's OpenBLAS, loaded after the finder is installed, start their
  thread pools idle (:mod:`mitld_lp.util.blas_idle`, a finder placed after this one).

:func:`mitld_lp.startup.package_imports_held` installs the finder at the first of the
package's modules to import, but for the robot's runtime (``mitld_lp.runtime``, the
saved controller's readers, ``mitld_lp.controllers``, ``mitld_lp.files``: NumPy alone).
A program that imported SciPy (or made the layer) before is left as it was; what the
command line's start did (:func:`mitld_lp.startup.lean_start`: every class's makers, the
collector off) is not done twice.  Nothing changes an answer: the same classes and
objects.  ``MITLD_LP_PLAIN_IMPORTS=1`` leaves the finder out (Python's plain imports).
"""

from __future__ import annotations

import _thread
import sys
import types

from mitld_lp.util import collector

TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Callable
    from importlib.machinery import ModuleSpec
    from types import ModuleType
    from typing import Any

__all__ = ["NUMPY_EXTRAS", "SCIPY_NUMPY_COPY", "Loader", "install", "installed", "inside",
           "numpy_listed_without_extras", "hand_over_extras", "scipy_copy_around", "spec_around"]

#: The package whose modules open the window.
PACKAGE = "mitld_lp"

#: The module where SciPy copies NumPy's namespace (``clone_module``), SciPy 1.15 on.
SCIPY_NUMPY_COPY = "scipy._lib.array_api_compat.numpy"

#: The ``dataclasses`` functions the package's makers replace while a body runs.
MAKERS = ("_repr_fn", "_cmp_fn", "_hash_fn", "_frozen_get_del_attr", "_create_fn")

_lock = _thread.RLock()  # the count below, for imports in several threads
_depth = 0  # package bodies running (nested, or in several threads)
_held = False  # whether the window turned the collector off
_stdlib: dict[str, Any] = {}  # dataclasses' own makers, put back when the window closes
_ours: dict[str, Any] = {}  # the package's makers, made once
_finder: _Finder | None = None


def inside() -> bool:
    """Whether a body of the package's modules is running (the window is open)."""
    return _depth > 0


def _open(makers: bool = True) -> Callable[[ModuleType | None], None]:
    """A package module's body starts: the window opens if it is the outermost (the
    package's dataclass makers in place unless ``makers`` is false: the makers' own
    modules); the function that closes it (called when the body ends, whatever
    happened)."""
    global _depth, _held
    import gc

    with _lock:
        _depth += 1
        if _depth == 1:
            _held = gc.isenabled()
            if _held:
                gc.disable()
            if makers and "dataclasses" in sys.modules:
                _makers_on()

    def close(_module: ModuleType | None) -> None:
        global _depth, _held
        with _lock:
            _depth -= 1
            if _depth == 0:
                _makers_off()
                if _held:  # on again, the imports' objects aged (no pass over them)
                    _held = False
                    collector.release()

    return close


def _dataclasses_imported() -> Callable[[ModuleType | None], None]:
    """``dataclasses`` imported inside the window: the package's makers after it."""

    def after(module: ModuleType | None) -> None:
        if module is not None and _depth > 0:
            _makers_on()

    return after


#: NumPy's submodules that it imports on first use, which SciPy's array-API layer would
#: import all at once and which no array-API function needs
#: (:func:`mitld_lp.startup.lean_scipy`).
NUMPY_EXTRAS = ("f2py", "testing", "ma", "random", "polynomial", "ctypeslib", "rec",
                "char", "strings", "core")



def numpy_listed_without_extras() -> tuple[Callable[[], None], set[str]]:
    """NumPy's ``__all__`` and ``dir`` without the names of :data:`NUMPY_EXTRAS` not
    imported yet, until the function returned is called (which puts both back); and
    those names.  :func:`mitld_lp.startup.lean_scipy`'s first half."""
    import numpy

    kept_all, kept_dir = numpy.__all__, vars(numpy).get("__dir__")
    listed = {*kept_all, *(kept_dir() if kept_dir is not None else ())}
    extras = {name for name in NUMPY_EXTRAS if name in listed and name not in vars(numpy)}
    numpy.__all__ = [name for name in kept_all if name not in extras]
    if kept_dir is not None:
        numpy.__dir__ = lambda: [name for name in kept_dir() if name not in extras]

    def restore() -> None:
        numpy.__all__ = kept_all
        if kept_dir is not None:
            numpy.__dir__ = kept_dir

    return restore, extras


def hand_over_extras(copy: Any, extras: set[str]) -> None:
    """SciPy's copy of NumPy's namespace, made while :func:`numpy_listed_without_extras`
    held ``extras`` back, hands each of them over from NumPy when first asked (importing
    it then) and lists them in its ``__all__``.  :func:`mitld_lp.startup.lean_scipy`'s
    second half."""
    import numpy

    left_out = extras - vars(copy).keys()
    own = vars(copy).get("__getattr__")  # a later SciPy's own, asked for the rest

    def handed_over(name: str) -> object:
        if name in left_out:
            return getattr(numpy, name)
        if own is not None:
            return own(name)
        raise AttributeError(f"module {SCIPY_NUMPY_COPY!r} has no attribute {name!r}")

    copy.__getattr__ = handed_over
    copy.__all__ = sorted({*copy.__all__, *left_out})


def scipy_copy_around() -> Callable[[ModuleType | None], None]:
    """Before SciPy's copy of NumPy's namespace runs: NumPy lists no extras; the
    function to call after it (NumPy put back, then the copy handing the extras over;
    ``None``: the import failed, NumPy is put back only)."""
    restore, extras = numpy_listed_without_extras()

    def after(copy: ModuleType | None) -> None:
        restore()
        if copy is not None:
            hand_over_extras(copy, extras)

    return after


def _makers_on() -> None:
    """``dataclasses`` makes the package's classes with the package's makers (the
    stdlib's for every other class); nothing if they are in place already (the command
    line's start put them there for every class)."""
    import dataclasses

    if _stdlib or getattr(getattr(dataclasses, "_repr_fn", None), "__module__",
                          None) != "dataclasses":
        return  # on already, or another's (the command line's, for every class)
    if not _ours:
        saved = {name: getattr(dataclasses, name, None) for name in MAKERS}
        from mitld_lp import init_cache
        from mitld_lp.dataclass_closures import methods_without_exec

        methods_without_exec(package_only=True)
        init_cache.install(package_only=True)
        _ours.update({name: getattr(dataclasses, name, None) for name in MAKERS})
        _stdlib.update(saved)
        return
    for name in MAKERS:
        if _ours[name] is not None:
            _stdlib[name] = getattr(dataclasses, name)
            setattr(dataclasses, name, _ours[name])


def _makers_off() -> None:
    """``dataclasses``'s own makers back (each one still the package's: one put in its
    place meanwhile is left where it is)."""
    if not _stdlib:
        return
    dataclasses = sys.modules.get("dataclasses")
    if dataclasses is not None:
        for name, own in _stdlib.items():
            if own is not None and getattr(dataclasses, name, None) is _ours.get(name):
                setattr(dataclasses, name, own)
    _stdlib.clear()


#: Other packages' modules the package imports inside its functions (not at a module's
#: top): when the package's code imports one of them, the window opens as for its own.
LATER = frozenset(("numba", "stormpy", "scipy.sparse.csgraph", "scipy.sparse.linalg",
                   "scipy.linalg", "scipy.optimize", "scipy.stats", "clarabel", "highspy",
                   "cvxpy", "lark"))


#: SciPy's sparse linear algebra, which ``scipy.sparse.csgraph`` imports at its start
#: for one name (``LinearOperator``), and its direct solvers' module (``splu``...), which
#: needs one name of ``scipy.linalg`` (``LinAlgError``, NumPy's own class).
SPARSE_LINALG = "scipy.sparse.linalg"
DIRECT_SOLVERS = "scipy.sparse.linalg._dsolve"
SCIPY_LINALG = "scipy.linalg"


class BodyLater(types.ModuleType):
    """A module whose ``__init__`` has not run yet: its spec, path and the names
    :data:`SERVED` gives for it are there; reading any other name, or ``dir``, runs the
    real ``__init__`` in this same module, which then is the plain module the import
    system makes (the names served are the ones its ``__init__`` binds)."""

    def _load(self) -> None:
        spec = vars(self)["__spec__"]
        self.__class__ = types.ModuleType  # no more stand-in, whatever happens below
        spec.loader.exec_module(self)

    def __getattr__(self, name: str) -> Any:
        serve = SERVED.get(vars(self)["__name__"])
        if serve is not None and not name.startswith("__"):
            found = serve(name)
            if found is not _NOT_SERVED:
                vars(self)[name] = found
                return found
        self._load()
        return getattr(self, name)

    def __dir__(self) -> list[str]:
        self._load()
        return dir(self)


_NOT_SERVED = object()


def _linear_operator(name: str) -> Any:
    """``scipy.sparse.linalg``'s names served before its ``__init__``: ``LinearOperator``
    (from ``_interface``, csgraph's one name) and the direct solvers (``splu``,
    ``spsolve``..., the names of ``_dsolve.__all__``, which the ``__init__`` binds with
    ``from ._dsolve import *``), imported with ``scipy.linalg`` left for later
    (:func:`linalg_later`)."""
    import importlib

    if name == "LinearOperator":
        return importlib.import_module(f"{SPARSE_LINALG}._interface").LinearOperator
    if name not in DIRECT_NAMES:
        return _NOT_SERVED
    linalg_later()
    direct = importlib.import_module(DIRECT_SOLVERS)
    return getattr(direct, name) if name in getattr(direct, "__all__", ()) else _NOT_SERVED


#: The names of ``scipy.sparse.linalg._dsolve`` (SciPy 1.17) served before the whole of
#: ``scipy.sparse.linalg``; one a SciPy release lacks loads the whole module.
DIRECT_NAMES = frozenset(("splu", "spilu", "spsolve", "factorized", "SuperLU",
                          "MatrixRankWarning", "spsolve_triangular", "use_solver",
                          "is_sptriangular", "spbandwidth"))


def _numpy_linalg_error(name: str) -> Any:
    """``scipy.linalg``'s one name served before its ``__init__``: ``LinAlgError``, which
    SciPy takes from NumPy (``scipy.linalg._misc``: ``from numpy.linalg import
    LinAlgError``)."""
    if name != "LinAlgError":
        return _NOT_SERVED
    import numpy.linalg

    return numpy.linalg.LinAlgError


#: What each stand-in serves before its ``__init__`` runs.
SERVED = {SPARSE_LINALG: _linear_operator, SCIPY_LINALG: _numpy_linalg_error}


def body_later(name: str) -> ModuleType | None:
    """``name`` (one of :data:`SERVED`) in ``sys.modules`` as a :class:`BodyLater` not run
    yet, bound in its parent package as the import system binds a submodule; the module
    already imported when it is (None when it cannot be found)."""
    if name in sys.modules:
        return sys.modules[name]
    import importlib
    import importlib.util

    parent_name, _, child = name.rpartition(".")
    parent = importlib.import_module(parent_name)
    spec = importlib.util.find_spec(name)
    if spec is None or spec.loader is None or not hasattr(spec.loader, "exec_module"):
        return None
    module = importlib.util.module_from_spec(spec)  # the import system's own
    module.__class__ = BodyLater
    sys.modules[name] = module
    vars(parent)[child] = module
    return module


def linalg_later() -> None:
    """``scipy.linalg`` left for later (a :class:`BodyLater`, serving ``LinAlgError``):
    SciPy's direct sparse solvers import it for that one name; its ``__init__`` (LAPACK
    and BLAS wrappers, the decompositions) is 0.05-0.07 s of CPU.  The first other name
    read loads it whole.  Nothing if it is imported already."""
    body_later(SCIPY_LINALG)


def _sparse_linalg_later(loader: Any, module: ModuleType) -> None:
    """The package's own import of ``scipy.sparse.linalg`` (its own ``import`` or
    csgraph's, inside the window): the module made as a :class:`BodyLater`, its
    ``__init__`` run when a name it does not serve is read."""
    module.__class__ = BodyLater


#: SciPy's array-API layer, which ``scipy._lib._util`` imports at its start for
#: :data:`LAYER_NAMES` and calls only inside functions that no sparse routine of the
#: package's reaches (``array_namespace``... for SciPy's array-API-aware functions).
ARRAY_API = "scipy._lib._array_api"
SCIPY_UTIL = "scipy._lib._util"
#: The names ``scipy._lib._util`` binds from the layer (SciPy 1.17), and the SciPy
#: releases checked to bind exactly these (another release imports the layer as usual).
LAYER_NAMES = ("Array", "array_namespace", "is_lazy_array", "is_numpy", "is_marray",
               "xp_size", "xp_result_device", "xp_result_type")
LAYER_SCIPY = ("1.17.",)


class LayerLater(BodyLater):
    """SciPy's array-API layer before its body has run: ``scipy._lib._util``'s own
    ``from scipy._lib._array_api import ...`` gets ``Array`` (``typing.Any``, the
    layer's own alias) and, for each function, a forwarder that runs the layer's body
    and calls SciPy's function; the body then puts SciPy's functions in place of the
    forwarders in ``scipy._lib._util``.  Any other reader (another module's ``from``
    import, an attribute, ``dir``) runs the body at once and gets SciPy's objects: the
    module is then the one the import system made, run as it would have been (inside
    the window, so its copy of NumPy's namespace is made as in the package's own
    import)."""

    def __getattr__(self, name: str) -> Any:
        if name == "__path__":  # not a package (the import system asks at ``from``)
            raise AttributeError(name)
        if name in LAYER_NAMES and sys._getframe(1).f_globals.get("__name__") == SCIPY_UTIL:
            return _layer_served(name)
        self._load()
        return getattr(self, name)

    def _load(self) -> None:
        close = _open(makers=False)
        try:
            BodyLater._load(self)
        finally:
            close(self)
        util = sys.modules.get(SCIPY_UTIL)
        if util is not None:
            for name, served in _layer_forwarders.items():
                if vars(util).get(name) is served:
                    setattr(util, name, getattr(self, name))


_layer_forwarders: dict[str, Any] = {}


def _layer_served(name: str) -> Any:
    """What the layer serves ``scipy._lib._util`` before its body runs."""
    if name == "Array":
        from typing import Any as array  # the layer's ``Array: TypeAlias = Any``

        return array
    forward = _layer_forwarders.get(name)
    if forward is None:
        def forward(*args: Any, **kwargs: Any) -> Any:
            layer = sys.modules[ARRAY_API]
            if isinstance(layer, LayerLater):
                layer._load()
            return getattr(layer, name)(*args, **kwargs)

        forward.__name__ = forward.__qualname__ = name
        forward.__doc__ = f"SciPy's {ARRAY_API}.{name}, its module run on the first call."
        _layer_forwarders[name] = forward
    return forward


def _layer_later(loader: Any, module: ModuleType) -> None:
    """``scipy._lib._util`` importing the layer inside the package's window, on a SciPy
    release of :data:`LAYER_SCIPY`: the module made as a :class:`LayerLater`."""
    module.__class__ = LayerLater


def _layer_checked() -> bool:
    version = getattr(sys.modules.get("scipy"), "__version__", "")
    return isinstance(version, str) and version.startswith(LAYER_SCIPY)


#: What lark imports at its start for its grammar loader and its cache alone, which a
#: parser loaded from stored tables (:mod:`mitld_lp.logic.tables`) never calls:
#: ``regex`` (grammars that ask for it), ``hashlib`` (the grammar's digest; OpenSSL's
#: start), ``getpass`` and ``tempfile`` (the cache file's name and folder) and
#: ``pkgutil`` (grammars imported from packages).
LARK_LATER = ("regex", "hashlib", "getpass", "tempfile", "pkgutil")


def _lark_around() -> Callable[[ModuleType | None], None]:
    """lark imported by the package (the window opened as for any package import): lark
    imports the modules of :data:`LARK_LATER` at its start (0.01-0.02 s of CPU), which
    the package's parser, loaded from its stored tables, never uses.  While lark's body
    runs, each one not imported yet is a stand-in (:func:`mitld_lp.stand_ins.later`)
    that lark binds and that imports the real module when lark first reads a name of it
    (building a parser from a grammar, its cache); the stand-ins leave ``sys.modules``
    when lark's import ends, so the program's own ``import hashlib`` is Python's as
    before.  lark sees each module installed, as it is, and behaves alike."""
    close = _open()
    import importlib.util

    from mitld_lp.stand_ins import later

    stand_ins = {}
    for name in LARK_LATER:
        if name not in sys.modules and importlib.util.find_spec(name) is not None:
            stand_ins[name] = sys.modules[name] = later(name)

    def after(module: ModuleType | None) -> None:
        try:
            for name, stand_in in stand_ins.items():
                if sys.modules.get(name) is stand_in:
                    del sys.modules[name]
        finally:
            close(module)

    return after


#: The modules the package's makers come from (their window cannot put them in place).
_MAKERS_OWN = frozenset((f"{PACKAGE}.dataclass_closures", f"{PACKAGE}.init_cache"))


def _open_without_makers() -> Callable[[ModuleType | None], None]:
    return _open(makers=False)


def _imported_by_package(imported: str = "") -> bool:
    """Whether the code importing now (the first frame outside ``importlib`` and outside
    a lazy package's ``__getattr__`` importing its submodule ``imported``, as
    ``from scipy.sparse import csgraph`` does on SciPy 1.17) is one of the package's
    modules."""
    frame = sys._getframe(2)
    while frame is not None:
        name = frame.f_globals.get("__name__", "")
        if not isinstance(name, str):
            return False
        if (name != __name__ and name.partition(".")[0] not in ("importlib",
                                                                 "_frozen_importlib")
                and not (frame.f_code.co_name == "__getattr__"
                         and imported.startswith(name + "."))):
            return name.partition(".")[0] == PACKAGE
        frame = frame.f_back
    return False


def _around(name: str) -> Callable[[], Callable[[ModuleType | None], None]] | None:
    """What runs around the import of ``name``; None: nothing (the finder steps aside)."""
    if name in _MAKERS_OWN:
        return _open_without_makers
    if name.startswith(PACKAGE + "."):
        return _open
    if name == SPARSE_LINALG and (_depth > 0 or _imported_by_package(name)):
        return _sparse_linalg_later
    if name == ARRAY_API and _depth > 0 and _layer_checked():
        return _layer_later
    if name == "lark" and (_depth > 0 or _imported_by_package(name)):
        return _lark_around
    if name == "numpy.ma":  # the package's np.unique asking for it: its body later
        from mitld_lp import masked_later
        return masked_later.made_later if masked_later.asked_by_unique() else None
    if _depth == 0 and name in LATER and _imported_by_package(name):
        return _open
    if _depth > 0:
        if name == "dataclasses":
            return _dataclasses_imported
        if name == SCIPY_NUMPY_COPY:
            return scipy_copy_around
    return None


class Loader:
    """The module's own loader for one import, with what runs around its
    ``exec_module`` (``around()`` before it, the function it returns after it, with the
    module, or None if the body failed); every other attribute is the loader's own."""

    def __init__(self, loader: Any, around: Any) -> None:
        self._loader, self._around = loader, around

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        loader = self._loader
        module.__loader__ = loader  # the module's own loader, as without the hook
        if module.__spec__ is not None:
            module.__spec__.loader = loader
        after = self._around()
        try:
            loader.exec_module(module)
        except BaseException:
            after(None)
            raise
        after(module)


class BodyLaterLoader(Loader):
    """The module's own loader for one import that does not run its body: ``around``
    makes the module a stand-in (:class:`BodyLater`) whose first use runs it."""

    def exec_module(self, module: ModuleType) -> None:
        loader = self._loader
        module.__loader__ = loader
        if module.__spec__ is not None:
            module.__spec__.loader = loader
        self._around(loader, module)


class _Finder:
    """The finder: the package's modules and, inside the window, ``dataclasses`` and
    SciPy's layer; each found by the finders after it, its loader wrapped for the one
    import (then put back on the module)."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> ModuleSpec | None:
        around = _around(name)
        if around is None:
            return None
        return spec_around(self, name, path, target, around)


def spec_around(skip: Any, name: str, path: Any, target: Any, around: Any) -> ModuleSpec | None:
    """The spec of ``name`` as the finders of ``sys.meta_path`` other than ``skip`` find
    it, its loader wrapped (:class:`Loader`) to run ``around`` about its body."""
    for finder in sys.meta_path:
        if finder is skip or not hasattr(finder, "find_spec"):
            continue
        spec = finder.find_spec(name, path, target)
        if spec is not None:
            if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                later = around in (_sparse_linalg_later, _layer_later) or name == "numpy.ma"
                spec.loader = (BodyLaterLoader if later else Loader)(spec.loader, around)
            return spec
    return None


def install() -> _Finder | None:
    """Put the finder at the front of ``sys.meta_path`` (once), and return it; nothing
    (None) when the environment asks for plain imports (``MITLD_LP_PLAIN_IMPORTS=1``)."""
    global _finder
    import os

    with _lock:  # once, whichever thread imports first
        if _finder is None and os.environ.get("MITLD_LP_PLAIN_IMPORTS") != "1":
            _finder = _Finder()
            sys.meta_path.insert(0, _finder)
            from mitld_lp.util import blas_idle  # OpenBLAS's pools idle at once

            blas_idle.install(after=_finder)
    return _finder


def installed() -> bool:
    """Whether the finder is in place."""
    return _finder is not None
