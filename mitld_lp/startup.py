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
"""

from __future__ import annotations

# _signal, not signal: the C module is built into the interpreter and imports at once,
# while signal.py builds its enums first (a Ctrl-C landing there printed a traceback)
import _signal
import os
import sys

__all__ = ["started_as_command", "command", "collect_from_here"]


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
    from mitld_lp.cli import run

    run()
