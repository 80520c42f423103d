"""What must happen before anything heavy is imported, and the console script.

``mitld-lp`` is :func:`command`: the verb ``run`` goes to :func:`mitld_lp.runtime.main`,
which imports NumPy alone (a robot's process runs it without the solver stack), and
every other verb to :func:`mitld_lp.cli.run`.

Started as the command line (``mitld-lp``, or ``python -m mitld_lp`` while Python locates
the module and ``sys.argv[0]`` is ``"-m"``), a Ctrl-C during the package's import prints
one line and exits 130 instead of a traceback; :func:`mitld_lp.cli.run` hands Ctrl-C back
to Python's own handling once it is imported (its command thread then reacts to it).
A program that imports the package is left alone.

The command line also asks the BLAS libraries under NumPy and SciPy for one thread each
(``OPENBLAS_NUM_THREADS``, ``MKL_NUM_THREADS``; a value the user set is kept).  Nothing
in a command calls dense BLAS on large operands (the solvers are sparse and single
threaded, and a sweep runs one process per core), yet each library starts a pool of
one thread per core at import whose spinning cost 0.2 s of CPU on a 2-core machine, a
third of solving the bundled case study; the cost grows with the core count.

The command line also starts with Python's cyclic garbage collector off, and
:func:`collect_from_here` turns it back on, with every object made so far (the imported
modules' functions, classes and tables) moved out of its reach (``gc.freeze``), when the
command's work starts.  Imports make no garbage cycles worth collecting, yet the
collector, triggered by their allocations, walked every object already imported over
and over (a full pass over NumPy, SciPy and the package): about 0.03 s of the bundled
case's CPU, and each later pass of the solve walked them again.

Before the command line is imported, :func:`command` also imports SciPy's array-API
layer without the NumPy submodules no command uses (:func:`lean_scipy`), and has lark,
if a formula the plain parser leaves (:mod:`mitld_lp.logic.plain_parse`) imports it,
import without the ``regex`` package
(:func:`mitld_lp.library_start.lark_without_regex`): 0.085 s of the bundled case's
CPU.  It also puts off ``numpy.ma``, which the first ``np.unique`` would import, until
a masked array is asked for (:func:`numpy_ma_when_used`: 0.012 s).
These leave every name where it was (the layer hands NumPy's submodules over when
asked; ``regex`` and ``numpy.ma`` import for whoever asks later).  A program that
imports the package gets NumPy, SciPy and lark as they import themselves, but for the
cuts nobody can see, made while the package's own modules import
(:mod:`mitld_lp.own_imports`: the collector held and put back, SciPy's layer as here
when the package imports it, the package's own dataclasses as below, not the
program's, ``scipy.sparse.csgraph`` and the direct sparse solvers without
``scipy.linalg`` when the package imports them, lark's ``regex`` when lark uses it),
and on request (:mod:`mitld_lp.library_start`) the csgraph cut for the program's own
imports (the command line too).

First of all, :func:`command` has the dataclasses the command line imports (about 120,
nearly all frozen) made with their comparison, hash, representation and frozen
methods as closures instead of source compiled one method at a time
(:func:`dataclass_methods_without_exec`): about 0.05 s of the bundled case's CPU; and
their ``__init__`` methods from code compiled by an earlier run
(:mod:`mitld_lp.init_cache`): 0.03 s more.
"""

from __future__ import annotations

# _signal, not signal: the C module is built into the interpreter and imports at once,
# while signal.py builds its enums first (a Ctrl-C landing there printed a traceback)
import _signal
import os
import sys

# typing is not imported before the Ctrl-C handler below (a Ctrl-C landing in its import
# printed a traceback); the names are for annotations only
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

__all__ = ["started_as_command", "package_imports_held", "command", "collect_from_here",
           "hold_collector", "lean_start",
           "lean_scipy", "lark_without_regex", "dataclass_methods_without_exec",
           "numpy_ma_when_used"]


def started_as_command() -> bool:
    """Whether this process is the command line, judged from ``sys.argv[0]``."""
    first = sys.argv[0] if sys.argv else ""
    return os.path.basename(first) == "mitld-lp" or first == "-m"


def _interrupted(_signum: int, _frame: object) -> None:
    os.write(2, b"mitld-lp: interrupted\n")
    os._exit(130)


#: The thread-pool sizes the command line sets before NumPy is imported.
BLAS_THREADS = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


#: Whether this module turned the garbage collector off (the command line's start-up).
_collector_held = False

if started_as_command():
    _signal.signal(_signal.SIGINT, _interrupted)
    for _name, _value in BLAS_THREADS.items():
        os.environ.setdefault(_name, _value)
    import gc  # after the handler: a Ctrl-C may land on any line before it

    if gc.isenabled():
        gc.disable()
        _collector_held = True


#: The package's modules a first import of which leaves the imports as Python makes them:
#: the robot's runtime and what it reads a saved controller with (NumPy alone beside).
PLAIN_FIRST = ("mitld_lp.runtime", "mitld_lp.controllers", "mitld_lp.files",
               "mitld_lp.own_imports")


class _FirstImport:
    """A finder waiting for the first import of one of the package's modules (not one
    of :data:`PLAIN_FIRST`): it then steps aside for :mod:`mitld_lp.own_imports`'s."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if not name.startswith("mitld_lp.") or name.startswith(PLAIN_FIRST):
            return None
        try:
            sys.meta_path.remove(self)
        except ValueError:
            pass
        from mitld_lp import own_imports

        finder = own_imports.install()
        return finder.find_spec(name, path, target) if finder is not None else None


def package_imports_held() -> None:
    """``import mitld_lp`` calls it: the package's modules will import with the collector
    held and the package's dataclass makers (:mod:`mitld_lp.own_imports`, installed at
    the first import of one of them, which the robot's runtime never makes)."""
    sys.meta_path.insert(0, _FirstImport())


def collect_from_here() -> None:
    """The command's work starts: the garbage collector, off since the command line's
    start-up, is turned on again, and what exists now (the imported modules) is left
    out of its passes.  Nothing when the collector was not turned off here (a program
    that imports the package, a test calling :func:`mitld_lp.cli.main`)."""
    global _collector_held
    if _collector_held:
        import gc

        _collector_held = False
        gc.freeze()
        collector = sys.modules.get("mitld_lp.util.collector")  # (the runtime's: none)
        if collector is not None:  # the package's later imports: no count of the frozen
            collector.leave_frozen()
        gc.enable()


def command() -> None:
    """The ``mitld-lp`` console script (and ``python -m mitld_lp``): ``run`` is answered
    by :func:`mitld_lp.runtime.main` with NumPy alone, before anything of the command
    line is imported (its verbs' modules load the parser, the solvers' records and
    SciPy); ``--version`` here too; every other verb, and ``run`` with ``--time-limit``
    (whose watcher is the command line's), by :func:`mitld_lp.cli.run`."""
    argv = sys.argv[1:]
    if argv == ["--version"]:  # the answer argparse gives, without the command line
        from mitld_lp import __version__

        sys.stdout.write(f"mitld-lp {__version__}\n")
        sys.exit(0)
    if argv[:1] == ["run"] and not any(a.startswith("--ti") for a in argv[1:]):
        from mitld_lp.runtime import main

        collect_from_here()
        sys.exit(main(argv[1:]))
    lean_start()
    from mitld_lp.cli import run

    run()


def lean_start() -> None:
    """The command line's start-up, before anything heavy is imported: the dataclass
    methods as closures and their ``__init__`` code from the table of an earlier run
    (:func:`dataclass_methods_without_exec`, :mod:`mitld_lp.init_cache`), SciPy's
    array-API layer without NumPy's extra submodules (:func:`lean_scipy`), ``numpy.ma``
    when first used (:func:`numpy_ma_when_used`), lark without ``regex`` when a formula
    needs it (:func:`mitld_lp.library_start.lark_without_regex`), and the stand-ins of
    :mod:`mitld_lp.stand_ins`: NumPy without the docstrings of its C objects, SciPy's
    test runner and a few standard modules imported when first used; and
    ``scipy.sparse.csgraph`` without ``scipy.linalg``
    (:func:`mitld_lp.library_start.sparse_linalg_later`, the one cut of the program's
    start it keeps).

    :func:`command` calls it; a program that runs the package's routes and nothing else
    (a benchmark's worker process measuring what the command line's process costs) may
    call it first, before NumPy, SciPy and lark are imported; what each of those
    functions changes then holds for the whole process.  The answers are the same to
    the bit."""
    from mitld_lp import library_start

    library_start.install(command=True)  # a program's cuts: these are wider
    dataclass_methods_without_exec()
    from mitld_lp import init_cache

    init_cache.install()
    from mitld_lp import stand_ins

    stand_ins.numpy_docs_left_out()
    stand_ins.scipy_tests_when_used()
    stand_ins.modules_when_used()
    lean_scipy()
    numpy_ma_when_used()


def hold_collector() -> None:
    """Turn Python's cyclic garbage collector off while the imports run, as the command
    line does from its first line; :func:`collect_from_here` turns it back on when the
    work starts.  Nothing if it is off already."""
    global _collector_held
    import gc

    if gc.isenabled():
        gc.disable()
        _collector_held = True


def lean_scipy() -> None:
    """Import SciPy's array-API layer (which every ``scipy.sparse`` import loads) without
    the NumPy submodules in :data:`mitld_lp.library_start.NUMPY_EXTRAS`.

    The layer copies NumPy's namespace name by name (``from numpy import *`` and a
    ``getattr`` of every name ``dir(numpy)`` lists), and so imports every submodule NumPy
    keeps for first use -- ``numpy.f2py`` (which compiles a hundred regular
    expressions), ``numpy.testing``, ``numpy.ma``, ``numpy.polynomial``...: about 0.08 s
    of CPU, a fifth of solving the bundled case, for modules no command needs at its
    start (``numpy.ma`` is imported later by ``numpy.unique``, when it runs).  Here the
    copy is made with those names out of NumPy's ``__all__`` and ``dir``, which are put
    back at once, and the copy hands them over from NumPy when asked (a module
    ``__getattr__``, importing them then): the layer sees the same objects, later.

    The command line does it at its start; a program importing the package has it
    done when the package's import makes SciPy import the layer
    (:mod:`mitld_lp.own_imports`), or whenever SciPy does if it asked for
    :mod:`mitld_lp.library_start` (the same two halves); nothing when the layer is
    already imported or this SciPy has no such module."""
    import importlib

    from mitld_lp.library_start import (
        SCIPY_NUMPY_COPY,
        hand_over_extras,
        numpy_listed_without_extras,
    )

    if SCIPY_NUMPY_COPY in sys.modules:
        return

    restore, extras = numpy_listed_without_extras()
    try:
        copy = importlib.import_module(SCIPY_NUMPY_COPY)
    except ImportError:  # another SciPy: its own import, later, is left as it is
        return
    finally:
        restore()
    hand_over_extras(copy, extras)


def numpy_ma_when_used() -> None:
    """Put off NumPy's masked arrays (``numpy.ma``) until a masked array or one of the
    module's names is asked for.

    ``np.unique(values)`` asks ``np.ma.is_masked(values)`` first, which imports
    ``numpy.ma`` (0.012 s of CPU) on the first call of a process, for a plain array
    whose answer is False: no array made before that import can be masked, and a plain
    ``numpy.ndarray`` has no mask.  Here ``numpy.ma`` is a stand-in module whose
    ``is_masked`` answers False for an exact ``numpy.ndarray`` and asks the real
    function otherwise; any other name imports the real module (which then replaces the
    stand-in as ``numpy.ma``) and is its object.

    The command line only (a program importing the package gets the narrower cut of
    :mod:`mitld_lp.masked_later`: the module itself, its body run at first use, when the
    package's own ``np.unique`` imports it); nothing when ``numpy.ma`` is already
    imported."""
    import types

    import numpy

    if "numpy.ma" in sys.modules or "ma" in vars(numpy):
        return

    class Later(types.ModuleType):
        def __getattr__(self, name: str) -> Any:
            import numpy.ma as real  # numpy.ma is now the real module

            return getattr(real, name)

    def is_masked(x: object) -> Any:
        if type(x) is numpy.ndarray:
            return False
        import numpy.ma as real

        return real.is_masked(x)

    stand_in = Later("numpy.ma", "NumPy's masked arrays, imported when first used "
                                 "(mitld_lp.startup.numpy_ma_when_used).")
    stand_in.is_masked = is_masked  # type: ignore[attr-defined]
    numpy.ma = stand_in  # type: ignore[attr-defined]


def lark_without_regex() -> None:
    """Import lark now as where the ``regex`` package is not installed (it is not one of
    lark's requirements): lark imports ``regex`` at once when it can, for grammars
    that ask for it (``Lark(regex=True)``, Unicode categories), which the formula
    grammar does not; its import is 0.012 s of CPU.  Another package that imports
    ``regex`` later gets it as usual.  The command line's start no longer calls it:
    it waits for lark's import instead
    (:func:`mitld_lp.library_start.lark_without_regex`), which a plain formula never
    makes.

    For the command line only (a program importing the package may build its own lark
    grammars with ``regex=True``); nothing when lark or ``regex`` is already imported."""
    if "lark" in sys.modules or "regex" in sys.modules:
        return
    sys.modules["regex"] = None  # type: ignore[assignment]  # ``import regex`` fails
    try:
        import lark  # noqa: F401
    except ImportError:  # no lark: the command line says so where it needs it
        pass
    finally:
        del sys.modules["regex"]


def dataclass_methods_without_exec(package_only: bool = False) -> None:
    """:func:`mitld_lp.dataclass_closures.methods_without_exec`: a dataclass's
    comparison, hash, representation and frozen methods as closures instead of source
    compiled with ``exec`` (about 0.05 s of the bundled case's CPU); every class's, or
    the package's only (``package_only``)."""
    from mitld_lp.dataclass_closures import methods_without_exec

    methods_without_exec(package_only)
