"""The command line's kernel: what every verb shares, below all of them (the verbs import
it, it imports no verb).  Exit codes (:mod:`mitld_lp.cli`), the user errors and budget
stops they map, output files, the answer's lines, the options every model verb takes and
the problem those options pose (:func:`mitld_lp.synthesis.pose`)."""

from __future__ import annotations

import argparse
import glob
import json
import math
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mitld_lp import defaults
from mitld_lp.automata.translate import AutomatonTooLarge, TranslationError
from mitld_lp.cli.arguments import bands_reading, bounded_int, memory_size, probability_budget
from mitld_lp.controllers.format import ControllerFileError
from mitld_lp.distributions import DistributionError
from mitld_lp.exact.errors import ExactError
from mitld_lp.files import write as files
from mitld_lp.logic.fragment import FragmentError
from mitld_lp.logic.parser import ParseError
from mitld_lp.model import ModelError
from mitld_lp.problem import ProblemError
from mitld_lp.product import ProductTooLarge
from mitld_lp.report import bracket_text, probability_text
from mitld_lp.util import progress
from mitld_lp.util.clock import Deadline
from mitld_lp.util.text import printable

if TYPE_CHECKING:
    from mitld_lp.model import Model
    from mitld_lp.problem import Posed, Settings
    from mitld_lp.routes.stages import Built

PROG = "mitld-lp"

class UsageError(ValueError):
    """A bad command-line argument or output path (exit 2)."""


#: Exceptions that mean "the input is wrong" (exit 2), not "the program is wrong".
#: The sweep file's :class:`~mitld_lp.sweep.spec.SweepError` is one too
#: (:func:`user_errors`), known without importing the sweep package.
USER_ERRORS: tuple[type[Exception], ...] = (
    ExactError,
    ParseError,
    FragmentError,
    ModelError,
    DistributionError,
    TranslationError,
    UsageError,
    files.OutputPathError,
    FileExistsError,
    ProblemError,
    ControllerFileError,
)

#: User errors whose modules the command line does not import for them, as (module,
#: class): a verb that can raise one has imported its module, and an exception of a
#: class whose module was never imported cannot have been raised.  The sweep package
#: is imported by ``sweep`` and a batch only (0.015 s of CPU the bundled case's
#: ``solve`` did not need).
LATE_USER_ERRORS: tuple[tuple[str, str], ...] = (("mitld_lp.sweep.spec", "SweepError"),)


def user_errors() -> tuple[type[Exception], ...]:
    """:data:`USER_ERRORS` and the classes of :data:`LATE_USER_ERRORS` whose modules
    are imported by now: every user error this process can have raised."""
    late = tuple(getattr(sys.modules[module], name) for module, name in LATE_USER_ERRORS
                 if module in sys.modules)
    return USER_ERRORS + late


#: Exceptions that mean "a budget stopped the work" (exit 3).
BUDGET_STOPS: tuple[type[Exception], ...] = (ProductTooLarge, AutomatonTooLarge)

#: 3: no certified answer (a solver status or a budget stop; the status is printed).
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNCERTIFIED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


# --------------------------------------------------------------------------- errors as JSON

#: The statuses of the error object and the exit code of each: the input (a model file,
#: a formula, a sweep file, the problem they pose) is wrong; an argument or output path
#: is wrong; a budget stopped the work; the time limit did; Ctrl-C did; a bug.  A batch's
#: line and a sweep's row use the same statuses for the same causes.
ERROR_EXITS: dict[str, int] = {"model_error": EXIT_USAGE, "usage_error": EXIT_USAGE,
                               "budget": EXIT_UNCERTIFIED, "time_limit": EXIT_UNCERTIFIED,
                               "interrupted": EXIT_INTERRUPTED, "error": EXIT_INTERNAL}

#: The user errors that are about the command line itself (the rest: the input).
_USAGE_ERRORS: tuple[type[Exception], ...] = (UsageError, files.OutputPathError,
                                              FileExistsError)


def error_record(status: str, message: str, **more: Any) -> dict[str, Any]:
    """The one JSON error object of every verb that takes ``--json`` (docs/results.md,
    "Errors as JSON"): ``{"status", "error", "exit"}``, the reason as the error line on
    stderr says it, and ``more`` (a formula's ``line`` and ``column``; a batch line's
    ``file``)."""
    return {"status": status, "error": printable(message), "exit": ERROR_EXITS[status],
            **more}


def error_status(err: BaseException) -> str:
    """The error object's status of an exception the command line maps to an exit code."""
    if isinstance(err, BUDGET_STOPS + (MemoryError,)):
        return "budget"
    if isinstance(err, _USAGE_ERRORS):
        return "usage_error"
    return "model_error" if isinstance(err, user_errors()) else "error"


def say_error(args: argparse.Namespace | None, status: str, message: str,
              err: BaseException | None = None) -> int:
    """The one line on stderr (``error:``, ``stopped:`` or ``internal error:``) and, with
    ``--json``, the error object on stdout; the exit code of ``status``.  The command
    has ended: a bar its error left drawn is erased first."""
    progress.abandon()
    word = {"model_error": "error", "usage_error": "error", "error": "internal error"}.get(
        status, "stopped")
    say(message if status == "interrupted" else f"{word}: {message}")
    if args is not None and getattr(args, "json", False):
        formula = err  # a formula's error, also as the cause of a model's or a sweep's
        while formula is not None and not isinstance(formula, ParseError):
            formula = formula.__cause__
        where: dict[str, Any] = (  # a formula's place (in a model file: in its spec)
            {"line": formula.line, "column": formula.column}
            if isinstance(formula, ParseError) else
            {"reasons": list(err.reasons)} if isinstance(err, ProblemError) else {})
        if getattr(args, "verb", None) == "check":  # check's own answer field
            where["supported"] = False
        say_answer(json_text(error_record(status, message, **where)))
        sys.stdout.flush()
    return ERROR_EXITS[status]


# --------------------------------------------------------------------------- output files


def output_path(given: str, force: bool, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Check, before any work, that ``given`` can be written (the one rule,
    :func:`mitld_lp.files.write.writable_path`)."""
    return files.writable_path(given, overwrite=force, suffixes=suffixes, what=what,
                               force="--force")


DOT_SUFFIXES = (".dot", ".gv")


def write_file(path: Path, write: Callable[[Path], object]) -> None:
    """Run ``write(path)`` (a writer of :mod:`mitld_lp.files.write`, which replaces the file
    only once it is complete); an OS error (disk full, no permission) is a one-line
    error."""
    try:
        write(path)
    except OSError as exc:
        raise UsageError(f"{path}: cannot write: {exc.strerror or exc}") from exc


def json_text(record: object) -> str:
    """JSON with non-finite numbers as ``null`` (``NaN`` is not JSON)."""

    def clean(x: object) -> object:
        if isinstance(x, float) and not math.isfinite(x):
            return None
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        return x

    return json.dumps(clean(record), allow_nan=False)


command_state = threading.local()
"""Per command thread: ``cancelled``, an Event set when the command was interrupted or
ran out of time.  Its thread may still be finishing a native call, and must not print
an answer after the stop was reported."""


def prob_text(x: float) -> str:
    """A probability for text output: 7 decimals, or 7 significant digits below 1e-3."""
    return probability_text(x)


def _bracket(lower: float, upper: float) -> str:
    """A certified bracket for text output, its digits rounded outward."""
    return bracket_text(lower, upper)


def say_answer(text: str = "") -> None:
    """Print one line of the command's answer on stdout (nothing once cancelled; a
    progress bar drawn on the terminal is cleared first, :func:`progress.write`)."""
    cancelled = getattr(command_state, "cancelled", None)
    if cancelled is None or not cancelled.is_set():
        progress.write(text, sys.stdout)


def count_text(n: int, noun: str) -> str:
    """``n`` with ``noun`` in the singular or plural: "1 clock", "2 clocks"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def args_json(p: argparse.ArgumentParser) -> None:
    """``--json``, the same for every verb that takes it."""
    p.add_argument("--json", action="store_true",
                   help='print one JSON object on stdout, also for an error ({"status", '
                        '"error", "exit"}); no progress bars')


# --------------------------------------------------------------------------- model verbs


def add_model_argument(p: argparse.ArgumentParser, many: bool = False) -> None:
    if many:
        p.add_argument("model", nargs="+", help="model files or glob patterns (a batch: "
                       "one line per model)")
    else:
        p.add_argument("model", help="a model file (models/*.toml)")
    p.add_argument("--epsilon", type=probability_budget,
                   help="truncation budget in (0, 1) (default: the model's)")
    p.add_argument(
        "--no-clock-reduction",
        action="store_true",
        help="give every event an age clock, truncated as in the paper",
    )
    p.add_argument("--max-states", type=bounded_int(1), metavar="N",
                   help="refuse products (and automata) larger than N states (exit 3; "
                        "default: the model file's [budgets], else "
                        f"{defaults.MAX_STATES:,})")
    p.add_argument("--max-world-states", type=bounded_int(1), metavar="N",
                   help="refuse a world (a PRISM program, a gymnasium table) whose "
                        "exploration passes N states (exit 3; default: the model file's "
                        f"[budgets], else {defaults.MAX_STATES:,})")
    p.add_argument("--max-automaton-states", type=bounded_int(1), metavar="N",
                   help="refuse automata larger than N states (exit 3; default: the model "
                        f"file's [budgets], else {defaults.MAX_AUTOMATON_STATES:,})")
    p.add_argument("--max-memory", type=memory_size, metavar="SIZE",
                   help="refuse products needing more memory, e.g. 4G or 500M (exit 3; "
                        "default: the model file's [budgets], else half the machine's "
                        "memory)")
    p.add_argument("--precision", type=probability_budget, metavar="P",
                   help="the relative width a certified bracket may have, in (0, 1): "
                        "upper - lower <= P x lower (with truncation, the solver's part "
                        f"of the width; default {defaults.PRECISION:g})")
    p.add_argument("--bands", type=bands_reading, default="worst", metavar="READING",
                   help="how a law known only within a band is read: worst (the worst law "
                        "for the robot, guaranteed: Pmaxmin, the default) or best (the best "
                        "law for it, Pmaxmax: no guarantee under a law nature chooses)")


def read_model(args: argparse.Namespace, path: str | None = None,
               max_states: int | None = None) -> Model:
    """The model file ``path`` (default ``args.model``) under the verb's world budgets;
    a file that is plainly something else (a sweep file, a PRISM program) is refused
    saying what it is and which command or table takes it."""
    from mitld_lp.model import load_model

    path = args.model if path is None else path
    memory = getattr(args, "max_memory", None)
    try:
        return load_model(path, max_memory=memory, max_states=max_states if max_states
                          is not None else getattr(args, "max_world_states", None))
    except ModelError as err:
        what = other_file(path, memory, "model")
        if what:
            raise ModelError(f"{err}; {what}") from None
        raise


#: What a file is, by its suffix or its top-level keys, and where it goes.
_OTHER_FILES = {
    "prism": "it is a PRISM program: a model file names it as its world, [prism] file = "
             "\"...\" (docs/worlds.md; models/corridor.toml)",
    "sweep": "it is a sweep file: run it with mitld-lp sweep (docs/sweeps.md)",
    "model": "it is a model file: solve it with mitld-lp solve; a sweep file names its "
             "model, model = \"...\" (docs/sweeps.md)",
}


def other_file(path: str, max_memory: int | None, expected: str) -> str:
    """Why the file at ``path``, which did not read as a ``expected`` file ("model" or
    "sweep"), is another kind of file ("" when it is not plainly one)."""
    import tomllib

    from mitld_lp.files import rules

    if Path(path).suffix.lower() in (".prism", ".pm", ".nm"):
        return _OTHER_FILES["prism"]
    try:
        doc = tomllib.loads(rules.read_bytes(path, rules.read_limit(max_memory)).decode())
    except (OSError, ValueError, RecursionError, rules.InputFileError):
        return ""  # the reader's own error says it
    kind = ("sweep" if "model" in doc and "spec" not in doc else
            "model" if "spec" in doc and "model" not in doc else "")
    return _OTHER_FILES[kind] if kind and kind != expected else ""


def build_for(args: argparse.Namespace, verb: str) -> tuple[Posed, Built]:
    """Model file -> (the problem it poses, its automaton, STA and product MDP); a model
    with constraints is refused naming ``verb`` (its product would be another
    problem's)."""
    from mitld_lp.routes.stages import build_posed

    posed = posed_model(args, read_model(args), verb)
    if posed.route.observation_based:  # the fully observed product: another problem
        raise ProblemError(f"{verb}: the model has sensors that miss events: its problem is "
                           "solved on the information-state product (solve, simulate, "
                           "export --controller); this command would read the fully "
                           "observed product")
    return posed, build_posed(posed)


class TimeLimit:
    """The time limit the command's watchdog holds the work to (:func:`mitld_lp.cli.main`):
    ``seconds`` from ``started`` (monotonic), ``source`` saying whose limit it is for the
    stop line (empty for ``--time-limit``).  A batch replaces it while it runs a model
    whose file sets its own (:func:`file_time_limit`)."""

    __slots__ = ("seconds", "started", "source")

    def __init__(self, seconds: float | None, started: float, source: str = "") -> None:
        self.seconds, self.started, self.source = seconds, started, source

    def passed(self, grace: float) -> bool:
        return self.seconds is not None and time.monotonic() >= (
            self.started + self.seconds + grace)


def is_pattern(name: str) -> bool:
    """A glob pattern the shell did not expand (and no file of that name)."""
    return glob.has_magic(name) and not Path(name).exists()


def one_model_file(args: argparse.Namespace) -> str | None:
    """The one model file a command reads (None for a formula, a batch, a sweep, a
    results file, a controller)."""
    given = getattr(args, "model", None) if args.verb != "plot" else (
        None if Path(args.input).suffix.lower() in (".csv", ".parquet") else args.input)
    if isinstance(given, list):  # solve's: one file, or a batch
        given = given[0] if len(given) == 1 and not is_pattern(given[0]) else None
    return given if isinstance(given, str) else None


def file_time_limit(path: str, max_memory: int | None = None) -> TimeLimit | None:
    """The ``[budgets] time_limit`` of the model file ``path`` as the watchdog's limit,
    from now; None when it sets none.  A model file's budget binds as the flag does: every
    stage, the world's loading (a ``[python]`` factory) included."""
    from mitld_lp.model import model_budgets

    seconds = model_budgets(path, max_memory=max_memory).get("time_limit")
    if seconds is None:
        return None
    return TimeLimit(seconds, time.monotonic(), f" (the [budgets] time_limit of {path})")


def apply_file_time_limit(args: argparse.Namespace) -> None:
    """``--time-limit`` from the one model file's ``[budgets]`` when not given
    (:func:`file_time_limit`); ``args.limit`` the limit the watchdog holds."""
    args.limit = TimeLimit(args.time_limit, args.started)
    path = one_model_file(args) if args.time_limit is None else None
    limit = None if path is None else file_time_limit(path, getattr(args, "max_memory", None))
    if limit is not None:
        args.time_limit, args.limit = limit.seconds, TimeLimit(limit.seconds, args.started,
                                                               limit.source)


def time_left(args: argparse.Namespace) -> float | None:
    """Seconds left of ``--time-limit`` (None without one): the solvers stop with status
    ``time_limit`` and their bracket so far; the command's own watchdog is the backstop.
    A limit already spent is :data:`SPENT` seconds, not zero: the settings refuse a zero
    limit as a user error (exit 2, on a loaded machine where the model's loading ate the
    limit), while a spent one is the time-limit status (exit 3)."""
    left = Deadline.after(args.time_limit, args.started, time.monotonic).left()
    return left if left is None else max(left, SPENT)


#: The seconds :func:`time_left` gives for a time limit already spent.
SPENT = 1e-3


def say(message: str) -> None:
    progress.write(f"{PROG}: {printable(message)}", sys.stderr)
    sys.stderr.flush()



def model_options(args: argparse.Namespace) -> dict[str, Any]:
    """The settings every model verb's options set (:func:`add_model_argument`), as
    :func:`mitld_lp.synthesis.synthesize`'s keywords (time left now)."""
    return {"epsilon": args.epsilon, "clock_reduction": not args.no_clock_reduction,
            "max_states": args.max_states, "max_automaton_states": args.max_automaton_states,
            "max_memory": args.max_memory, "time_limit": time_left(args),
            "precision": defaults.PRECISION if args.precision is None else args.precision,
            "bands": args.bands}


def solve_settings(args: argparse.Namespace) -> Settings:
    """``solve``'s options as one :class:`mitld_lp.problem.Settings` (time left now)."""
    from mitld_lp.problem import settings_from

    return settings_from(method=args.method, solver=args.solver, backend=args.backend,
                         decompose=False if args.no_decompose else None, exact=args.exact,
                         **model_options(args))


def unconstrained(posed: Posed, verb: str) -> Posed:
    """``posed`` if it is not a constrained problem; a usage error naming the verb for a
    model whose file carries constraints (only ``solve``, ``sweep`` and ``pareto`` take
    them)."""
    if not posed.route.takes_constraints:
        return posed
    raise UsageError(f"{verb}: the model has constraints, which only solve, simulate, "
                     "sweep, pareto and export --controller/--chain/--tree take")


def posed_model(args: argparse.Namespace, model: Any, verb: str) -> Posed:
    """The problem a verb that takes no constraints (``simulate``, ``plot``, ``info``,
    ``export``) poses for ``model``: refused, naming the verb, when the model file
    carries constraints."""
    from mitld_lp.problem import settings_from
    from mitld_lp.synthesis import pose

    return unconstrained(pose(model, settings=settings_from(**model_options(args))), verb)


def print_head(model: Any, objective: str) -> None:
    """The first lines of a ``solve`` answer: the model, its task and a minimised
    objective."""
    say_answer(f"model:        {model.name}  ({model.spec})")
    if objective == "min":
        say_answer("objective:    min (the least probability of the task; the policy's "
                   "guarantee is the upper end)")


def probability_head(query: Any, bracket: str, decided: bool | None) -> str:
    """A ``P`` property's answer, ``in [l, u]``, or for ``P~p`` its verdict with the
    bracket that decides it."""
    if query.comparison is None:
        return f"in {bracket}"
    word = "Pmin" if query.objective == "min" else "Pmax"
    said = {True: "true", False: "false", None: "undecided"}[decided]
    return f"{said}: {word} in {bracket}, threshold {query.comparison} {query.threshold}"
