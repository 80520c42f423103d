"""The ``mitld-lp`` command: the registry of verbs, the worker thread, Ctrl-C and the
time limit.  What the verbs share is :mod:`mitld_lp.cli.kernel`; each verb lives in a
module of this package, imported only when it runs.

Each verb is a pair of functions, ``_args_<verb>(parser)`` adding its arguments and
``_cmd_<verb>(args) -> int`` running it, registered once in :data:`_VERBS`.  Exit codes:

* 0 -- done (a certified answer, for ``solve``);
* 2 -- the input is wrong (a bad argument, formula, model file or output path): one line
  ``mitld-lp: error: <reason>`` on stderr, checked before any work where it can be;
* 3 -- a solver or budget stop: the answer is not certified, a budget (``--max-states``,
  ``--time-limit``) was hit; the status is printed;
* 130 -- interrupted (Ctrl-C), within a fraction of a second, whatever the stage;
* 1 -- a bug: a one-line internal error.

Every message is one line of printable characters (names a user wrote are escaped).
This module is the only place in the package that prints.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any, NoReturn

from mitld_lp import startup
from mitld_lp.cli.arguments import seconds
from mitld_lp.cli.kernel import (
    BUDGET_STOPS,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_UNCERTIFIED,
    EXIT_USAGE,
    PROG,
    TimeLimit,
    UsageError,
    apply_file_time_limit,
    command_state,
    error_record,
    error_status,
    json_text,
    say,
    say_error,
    user_errors,
)
from mitld_lp.files import write as files
from mitld_lp.util import progress, watch
from mitld_lp.util.text import printable

__all__ = ["main", "run", "UsageError", "EXIT_OK", "EXIT_INTERNAL", "EXIT_USAGE",
           "EXIT_UNCERTIFIED", "EXIT_INTERRUPTED", "PROG"]


def _verb(module: str, name: str) -> Callable[..., Any]:
    """``mitld_lp.cli.<module>.<name>``, imported when the verb is asked for."""
    def call(arg: Any) -> Any:
        return getattr(importlib.import_module(f"mitld_lp.cli.{module}"), name)(arg)

    return call


# --------------------------------------------------------------------------- registry

#: (verb, one-line help, add arguments, run).  Add a verb by appending one row.
_VERBS: list[
    tuple[str, str, Callable[[argparse.ArgumentParser], None], Callable[[argparse.Namespace], int]]
] = [
    ("check", "parse a formula and check it is in the supported fragment",
     _verb("formulas", "args_check"), _verb("formulas", "cmd_check")),
    ("dta", "print the formula's automaton, or write it as DOT",
     _verb("formulas", "args_dta"), _verb("formulas", "cmd_dta")),
    ("info", "build the product of a model and print its sizes",
     _verb("solve", "args_info"), _verb("solve", "cmd_info")),
    ("solve", "synthesise the optimal policy and its certified bracket",
     _verb("solve", "args_solve"), _verb("solve", "cmd_solve")),
    ("export", "write the LP (MPS/LP) and the MDP (Storm DRN)",
     _verb("export", "args_export"), _verb("export", "cmd_export")),
    ("simulate", "Monte-Carlo rollouts of the synthesised controller",
     _verb("runs", "args_simulate"), _verb("runs", "cmd_simulate")),
    ("sweep", "solve a model at every point of a sweep, into a results file",
     _verb("runs", "args_sweep"), _verb("runs", "cmd_sweep")),
    ("plot", "draw a grid world's policy, or a column of a sweep's results",
     _verb("runs", "args_plot"), _verb("runs", "cmd_plot")),
    ("run", "answer JSON observations on stdin with a saved controller's actions",
     _verb("run", "args_run"), _verb("run", "cmd_run")),
    ("pareto", "the certified curve of success probability against steps, cost or a risk",
     _verb("constrained", "args_pareto"), _verb("constrained", "cmd_pareto")),
    ("warm", "compile the PRISM explorer and the solve's kernels once on this machine",
     _verb("warm", "args_warm"), _verb("warm", "cmd_warm")),
]


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: a bad argument raises :class:`UsageError`."""

    def error(self, message: str) -> NoReturn:  # type: ignore[override]
        if self.prog == PROG and "required: VERB" in message:  # bare `mitld-lp`
            message = "give a command: " + ", ".join(v for v, *_ in _VERBS)
        where = "" if self.prog == PROG else f"{self.prog}: "  # the line says PROG once
        raise UsageError(f"{where}{message} (see {self.prog} --help)")


def _build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser; given the words ``argv``, only the verb they name (the
    first word not an option) is added, with its arguments: the others' stay unread
    (their modules unimported), as a parse reads one verb's.  Each verb's parser costs
    about 0.5 ms of CPU to make (argparse's help formatter asks the terminal's size
    each time), 5 ms for the ten, a hundredth of the bundled case's process.  Words
    that name no verb (none, ``--help``, a misspelt verb) get every verb, for the list
    of verbs in the help and in the error."""
    asked = None if argv is None else next((w for w in argv if not w.startswith("-")), None)
    if asked not in {verb for verb, *_ in _VERBS}:
        asked = None
    parser = _Parser(
        prog=PROG,
        description="Policy synthesis for MITLD specifications by occupancy-measure LP.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {_version()}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    for verb, help_text, add_args, run in _VERBS:
        if asked not in (None, verb):
            continue
        p = sub.add_parser(verb, help=help_text, description=help_text)
        add_args(p)
        p.add_argument("-q", "--quiet", action="store_true",
                       help="no progress lines on stderr, only the answer and errors")
        p.add_argument("-v", "--verbose", action="store_true",
                       help="also the details of every stage (solver messages)")
        p.add_argument("--time-limit", type=seconds, metavar="SECONDS",
                       help="stop after SECONDS with status time_limit (exit 3; default: "
                            "the model file's [budgets] time_limit)")
        p.set_defaults(run=run)
    return parser


def _version() -> str:
    from mitld_lp import __version__

    return __version__


class _StageLines(logging.Handler):
    """Log records as printable lines on stderr (a progress bar drawn there is cleared
    first); the last one says where a stop was."""

    def __init__(self) -> None:
        super().__init__()
        self.last = ""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.last = printable(record.getMessage())
            progress.write(f"{PROG}: {self.last}", sys.stderr)
            sys.stderr.flush()
        except Exception:  # noqa: BLE001 - logging must never break the command
            self.handleError(record)


def _run(args: argparse.Namespace) -> int:
    """Run the verb; map every exception to an exit code, one line on stderr and, with
    ``--json``, the error object on stdout (:func:`mitld_lp.cli.kernel.say_error`)."""
    try:
        return args.run(args)
    except files.WriteAbandoned:  # interrupted from outside, which has said so
        return EXIT_INTERRUPTED
    except BUDGET_STOPS as err:  # before the user errors: some budgets subclass them
        return say_error(args, "budget", str(err), err)
    except user_errors() as err:  # (evaluated only when an exception arrives)
        return say_error(args, error_status(err), str(err), err)
    except BrokenPipeError:  # the reader (e.g. `| head`) went away: not an error
        sys.stderr.close()
        return EXIT_OK
    except MemoryError as err:
        return say_error(args, "budget", "out of memory (lower --max-states, or give the "
                         "machine more memory)", err)
    except Exception as err:  # noqa: BLE001 - the CLI never shows a traceback
        first = str(err).splitlines()[0] if str(err) else ""
        return say_error(args, "error", f"{type(err).__name__}: {first} (please report this)",
                         err)


_WATCHDOG_GRACE = 1.0
"""Seconds past ``--time-limit`` before the command is stopped from outside."""

#: The thread running the current command, if it is still running after ``main`` has
#: returned (interrupted or out of time): :func:`run` then ends the process at once.
_worker: threading.Thread | None = None


def main(argv: list[str] | None = None) -> int:
    """Run the command line ``argv`` (default ``sys.argv[1:]``); return the exit status.

    The command runs in a worker thread while this thread waits, so that Ctrl-C and
    ``--time-limit`` take effect within a tenth of a second whatever the stage is doing
    (the numerical kernels release the interpreter lock)."""
    args = _arguments(sys.argv[1:] if argv is None else argv)
    return args if isinstance(args, int) else _serve(args)


def _arguments(words: list[str]) -> argparse.Namespace | int:
    """The command's arguments, with its time limit (the flag's or its model file's), or
    the exit status once a usage error, ``--help`` or ``--version`` has been printed."""
    try:
        args = _build_parser(words).parse_args(words)
    except UsageError as err:  # no arguments yet: --json is looked for in the words
        return say_error(_json_asked(words), "usage_error", str(err))
    except SystemExit as stop:  # --help and --version have printed and exit 0
        return stop.code if isinstance(stop.code, int) else EXIT_USAGE
    args.started = time.monotonic()
    apply_file_time_limit(args)  # a model file's [budgets] time_limit binds as the flag
    return args


def _serve(args: argparse.Namespace) -> int:
    """Run the command ``args`` in the worker thread, this thread watching for Ctrl-C and
    the time limit (:func:`main`); its exit status."""
    global _worker
    cancelled = threading.Event()
    outcome: list[int] = []

    def work() -> None:
        command_state.cancelled = cancelled
        # bars on a terminal only, none under -q or --json (mitld_lp.util.progress)
        with progress.silenced(args.quiet or getattr(args, "json", False)):
            outcome.append(_run(args))

    startup.collect_from_here()  # the collector, off while the command line imported
    worker = threading.Thread(target=work, name=PROG, daemon=True)
    handler = _StageLines()  # this command's lines only, not an abandoned one's
    handler.addFilter(lambda record: record.thread == worker.ident)
    package_log = logging.getLogger("mitld_lp")
    if not args.quiet:
        package_log.addHandler(handler)
        package_log.setLevel(logging.DEBUG if args.verbose else logging.INFO)
    # The solvers get the limit itself and answer with a status; the watchdog stops a
    # stage that cannot (the product, a native call, a world's factory) shortly after it.
    # (args.limit: a batch replaces it while a model file's own limit runs.)
    try:
        worker.start()
        while worker.is_alive():
            worker.join(0.1)
            limit = args.limit
            if limit.passed(_WATCHDOG_GRACE) and worker.is_alive():
                cancelled.set()
                files.abandon(worker)
                progress.abandon()
                _time_stop(args, f" (last stage: {handler.last})" if handler.last else "",
                           limit)
                watch.report(watch.SAID)
                _worker = worker
                return EXIT_UNCERTIFIED
    except KeyboardInterrupt:
        cancelled.set()
        files.abandon(worker)  # a file half written is removed; the old one stays
        progress.abandon()
        say_error(args, "interrupted", "interrupted")
        watch.report(watch.SAID)
        _worker = worker
        return EXIT_INTERRUPTED
    finally:
        package_log.removeHandler(handler)
    return outcome[0] if outcome else EXIT_INTERNAL


def _time_stop(args: argparse.Namespace, where: str, limit: TimeLimit | None = None) -> None:
    """The time-limit stop: the stop line naming whose limit it was (``limit``, default
    the command's), and the error object with ``--json``."""
    limit = args.limit if limit is None else limit
    assert isinstance(limit, TimeLimit)
    message = f"time limit of {limit.seconds:g} s{limit.source} reached{where}"
    say(f"stopped: {message}")
    if getattr(args, "json", False):
        print(json_text(error_record("time_limit", message, time_limit=limit.seconds)),
              flush=True)


def _json_asked(words: list[str]) -> argparse.Namespace | None:
    """Arguments that ask for JSON (the verb and ``json``) when ``words``, which did not
    parse, hold ``--json`` before any ``--``; else None."""
    before = words[:words.index("--")] if "--" in words else words
    if "--json" not in before:
        return None
    return argparse.Namespace(json=True, verb=words[0] if words else None)


def run() -> None:
    """The ``mitld-lp`` console script: :func:`main`, then exit at once if interrupted
    or out of time (its thread may be in a native call the shutdown would abort)."""
    import signal

    signal.signal(signal.SIGINT, signal.default_int_handler)  # the import's handler ends
    try:
        args = _arguments(sys.argv[1:])  # read once (and the model file's budgets)
        # a time limit is kept from a parent process (watch.py), but not sweep's, whose
        # worker processes a killed parent would leave running: its points have their own
        if (isinstance(args, argparse.Namespace) and args.time_limit is not None
                and args.verb != "sweep"):
            limited = args
            code = watch.watched(limited.time_limit, lambda: _time_stop(
                limited, " (inside a long native call)"))
            if code is not None:
                sys.exit(code)
        code = args if isinstance(args, int) else _serve(args)
    except KeyboardInterrupt:  # before the command started (reading the arguments)
        say("interrupted")
        code = EXIT_INTERRUPTED
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # done: a late Ctrl-C changes nothing
    if _worker is not None:  # interrupted or out of time: no finalisation under a thread
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    _exit_done(code)


def _exit_done(code: int) -> NoReturn:
    """The command done: exit without the interpreter's teardown of every module and
    object (15-25 ms of CPU, 5-7 % of the bundled case's process) where nothing can run
    after it: the process is the command itself (:func:`_the_program`).  The exit
    handlers (``atexit``: logging's, the finalizers') run here, both streams are flushed,
    then ``os._exit``.  In a program that called the command's function (it may catch
    ``SystemExit`` and go on), with another Python thread alive (the interpreter would
    wait for it), no way to run the handlers, or a handler or flush that fails, the
    interpreter's own exit (``sys.exit``) as before."""
    import atexit

    handlers = getattr(atexit, "_run_exitfuncs", None)  # what the interpreter's exit runs
    if handlers is None or threading.active_count() != 1 or not _the_program():
        sys.exit(code)
    try:
        handlers()  # (each handler's own error is printed by atexit, as at exit)
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:  # noqa: BLE001 - the interpreter's exit says it as it did
        sys.exit(code)
    os._exit(code)


def _the_program() -> bool:
    """Whether the process's main module is the command: ``python -m mitld_lp`` or the
    console script the installer wrote (``mitld-lp``, whose module ends with
    ``sys.exit(command())``), not a program calling the command's function."""
    main = sys.modules.get("__main__")
    spec = getattr(main, "__spec__", None)
    if spec is not None:
        return bool(spec.name == "mitld_lp.__main__")
    name = os.path.basename(getattr(main, "__file__", None) or "")
    return name.removesuffix(".exe").removesuffix("-script.py") == PROG


if __name__ == "__main__":
    run()
