"""The command line's kernel: what every verb shares, below all of them (the verbs import
it, it imports no verb).  Exit codes (:mod:`mitld_lp.cli`), the user errors and budget
stops they map, output files, the answer's lines, the options every model verb takes and
the problem those options pose (:func:`mitld_lp.problem.pose`)."""

from __future__ import annotations

import argparse
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
from mitld_lp.cli.arguments import bounded_int, memory_size, probability_budget
from mitld_lp.distributions import DistributionError
from mitld_lp.files import write as files
from mitld_lp.logic.fragment import FragmentError
from mitld_lp.logic.parser import ParseError
from mitld_lp.model import ModelError
from mitld_lp.problem import CONSTRAINED, ProblemError
from mitld_lp.product import ProductTooLarge
from mitld_lp.report import bracket_text, probability_text
from mitld_lp.running.saved_plan import ControllerFileError
from mitld_lp.sweep.spec import SweepError
from mitld_lp.util.text import printable

if TYPE_CHECKING:
    from mitld_lp.problem import Posed, Settings
    from mitld_lp.routes.stages import Built

PROG = "mitld-lp"

class UsageError(ValueError):
    """A bad command-line argument or output path (exit 2)."""


#: Exceptions that mean "the input is wrong" (exit 2), not "the program is wrong".
_USER_ERRORS: tuple[type[Exception], ...] = (
    ParseError,
    FragmentError,
    ModelError,
    DistributionError,
    TranslationError,
    UsageError,
    files.OutputPathError,
    FileExistsError,
    SweepError,
    ProblemError,
    ControllerFileError,
)

#: Exceptions that mean "a budget stopped the work" (exit 3).
_BUDGET_STOPS: tuple[type[Exception], ...] = (ProductTooLarge, AutomatonTooLarge)

#: 3: no certified answer (a solver status or a budget stop; the status is printed).
EXIT_OK, EXIT_INTERNAL, EXIT_USAGE, EXIT_UNCERTIFIED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


# --------------------------------------------------------------------------- output files


def _output_path(given: str, force: bool, what: str, suffixes: tuple[str, ...] = ()) -> Path:
    """Check, before any work, that ``given`` can be written (the one rule,
    :func:`mitld_lp.files.write.writable_path`)."""
    return files.writable_path(given, overwrite=force, suffixes=suffixes, what=what,
                               force="--force")


_DOT_SUFFIXES = (".dot", ".gv")


def _write(path: Path, write: Callable[[Path], object]) -> None:
    """Run ``write(path)`` (a writer of :mod:`mitld_lp.files.write`, which replaces the file
    only once it is complete); an OS error (disk full, no permission) is a one-line
    error."""
    try:
        write(path)
    except OSError as exc:
        raise UsageError(f"{path}: cannot write: {exc.strerror or exc}") from exc


def _dumps(record: object) -> str:
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


_command = threading.local()
"""Per command thread: ``cancelled``, an Event set when the command was interrupted or
ran out of time.  Its thread may still be finishing a native call, and must not print
an answer after the stop was reported."""


def _prob(x: float) -> str:
    """A probability for text output: 7 decimals, or 7 significant digits below 1e-3."""
    return probability_text(x)


def _bracket(lower: float, upper: float) -> str:
    """A certified bracket for text output, its digits rounded outward."""
    return bracket_text(lower, upper)


def _out(text: str = "") -> None:
    """Print one line of the command's answer on stdout (nothing once cancelled)."""
    cancelled = getattr(_command, "cancelled", None)
    if cancelled is None or not cancelled.is_set():
        print(text)


def _count(n: int, noun: str) -> str:
    """``n`` with ``noun`` in the singular or plural: "1 clock", "2 clocks"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


# --------------------------------------------------------------------------- model verbs


def _args_model(p: argparse.ArgumentParser, many: bool = False) -> None:
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


def _build(args: argparse.Namespace, verb: str) -> tuple[Posed, Built]:
    """Model file -> (the problem it poses, its automaton, STA and product MDP); a model
    with constraints is refused naming ``verb`` (its product would be another
    problem's)."""
    from mitld_lp.model import load_model
    from mitld_lp.routes.stages import build_posed

    model = load_model(args.model, max_states=args.max_world_states,
                       max_memory=args.max_memory)
    posed = posed_model(args, model, verb)
    if posed.route == "sensed":  # the fully observed product would answer another problem
        raise ProblemError(f"{verb}: the model has sensors that miss events: its problem is "
                           "solved on the information-state product (solve, simulate, "
                           "export --controller); this command would read the fully "
                           "observed product")
    return posed, build_posed(posed)


def _time_left(args: argparse.Namespace) -> float | None:
    """Seconds left of ``--time-limit`` (None without one): the solvers stop with status
    ``time_limit`` and their bracket so far; the command's own watchdog is the backstop."""
    if args.time_limit is None:
        return None
    return max(args.time_limit - (time.monotonic() - args.started), 0.0)


def _say(message: str) -> None:
    print(f"{PROG}: {printable(message)}", file=sys.stderr, flush=True)



def model_options(args: argparse.Namespace) -> dict[str, Any]:
    """The settings every model verb's options set (:func:`_args_model`), as
    :func:`mitld_lp.synthesis.synthesize`'s keywords (time left now)."""
    return {"epsilon": args.epsilon, "clock_reduction": not args.no_clock_reduction,
            "max_states": args.max_states, "max_automaton_states": args.max_automaton_states,
            "max_memory": args.max_memory, "time_limit": _time_left(args),
            "precision": defaults.PRECISION if args.precision is None else args.precision}


def solve_settings(args: argparse.Namespace) -> Settings:
    """``solve``'s options as one :class:`mitld_lp.problem.Settings` (time left now)."""
    from mitld_lp.problem import settings_from

    return settings_from(method=args.method, solver=args.solver, backend=args.backend,
                         decompose=False if args.no_decompose else None,
                         **model_options(args))


def unconstrained(posed: Posed, verb: str) -> Posed:
    """``posed`` if it is not a constrained problem; a usage error naming the verb for a
    model whose file carries constraints (only ``solve``, ``sweep`` and ``pareto`` take
    them)."""
    if posed.route != CONSTRAINED:
        return posed
    raise UsageError(f"{verb}: the model has constraints, which only solve, simulate, "
                     "sweep, pareto and export --controller/--chain/--tree take")


def posed_model(args: argparse.Namespace, model: Any, verb: str) -> Posed:
    """The problem a verb that takes no constraints (``simulate``, ``plot``, ``info``,
    ``export``) poses for ``model``: refused, naming the verb, when the model file
    carries constraints."""
    from mitld_lp.problem import pose, settings_from

    return unconstrained(pose(model, settings=settings_from(**model_options(args))), verb)


def print_head(model: Any, objective: str) -> None:
    """The first lines of a ``solve`` answer: the model, its task and a minimised
    objective."""
    _out(f"model:        {model.name}  ({model.spec})")
    if objective == "min":
        _out("objective:    min (the least probability of the task; the policy's "
             "guarantee is the upper end)")
