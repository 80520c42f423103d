"""Solving one point (or one model file) and the record it leaves.

A point always gives a record: the synthesis's status and numbers, or, when it could not
be solved, a failure status and a one-line error.  Only an interrupt
(``KeyboardInterrupt``) leaves no record, so that the point is computed again next time.

Statuses: the solver's (``optimal``, ``inaccurate``, ``time_limit``, ...; see
:class:`mitld_lp.solvers.result.Status`), and

* ``model_error``: the point's model is invalid (a value out of range, a bad spec);
* ``budget``: a budget stopped it (``max_states``, ``max_memory``, out of memory);
* ``error``: a bug or an unexpected failure (the error names its type);
* ``lost``: the worker running it was lost and the retries were used up.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from mitld_lp.automata.translate import AutomatonTooLarge, TranslationError
from mitld_lp.distributions import DistributionError
from mitld_lp.exact.errors import ExactError
from mitld_lp.logic.constraints import ConstraintError
from mitld_lp.logic.fragment import FragmentError
from mitld_lp.logic.parser import ParseError
from mitld_lp.model import Model, ModelError
from mitld_lp.problem import ProblemError, Settings
from mitld_lp.product import ProductTooLarge
from mitld_lp.util.text import printable
from mitld_lp.worlds import WorldError
from mitld_lp.worlds.game import GameError
from mitld_lp.worlds.grid import GridError

__all__ = [
    "Settings",
    "PointTask",
    "run_model",
    "solve_point",
    "classify",
    "RESULT_COLUMNS",
    "TIME_COLUMNS",
    "META_COLUMNS",
    "RESERVED_COLUMNS",
    "MODEL_ERROR",
    "BUDGET",
    "ERROR",
    "LOST",
]

MODEL_ERROR, BUDGET, ERROR, LOST = "model_error", "budget", "error", "lost"

#: Exceptions meaning "this input is wrong".
INPUT_ERRORS: tuple[type[Exception], ...] = (
    ModelError, ParseError, FragmentError, DistributionError, TranslationError, WorldError,
    GameError, GridError, ProblemError, ConstraintError, ExactError,
)
#: Exceptions meaning "a budget stopped the work" (checked first: some subclass the above).
BUDGET_STOPS: tuple[type[BaseException], ...] = (ProductTooLarge, AutomatonTooLarge, MemoryError)

#: The record's columns after the parameters, with their types (``None`` when absent).
RESULT_COLUMNS: Mapping[str, type] = {
    "status": str,
    "certified": bool,
    "lower": float,
    "upper": float,
    "value": float,
    "epsilon_achieved": float,
    "dta_states": int,
    "states": int,
    "choices": int,
    "transitions": int,
    "seconds": float,
    "seconds_automaton": float,
    "seconds_product": float,
    "seconds_solve": float,
    "wall_seconds": float,
    "error": str,
}
#: Columns that measure time: they differ between two runs of the same point.
TIME_COLUMNS = ("seconds", "seconds_automaton", "seconds_product", "seconds_solve",
                "wall_seconds")
#: The columns naming the sweep a row belongs to, first in every results file.
META_COLUMNS = ("sweep", "sweep_id")
RESERVED_COLUMNS = frozenset(META_COLUMNS) | frozenset(RESULT_COLUMNS)

_STAGES = ("automaton", "product", "solve")


def classify(exc: BaseException) -> tuple[str, str]:
    """``(status, one-line message)`` of an exception raised while solving a model."""
    first = str(exc).splitlines()[0] if str(exc) else ""
    if isinstance(exc, BUDGET_STOPS):
        return BUDGET, printable(first or "out of memory")
    if isinstance(exc, INPUT_ERRORS):
        return MODEL_ERROR, printable(first)
    return ERROR, printable(f"{type(exc).__name__}: {first}")


@dataclass(frozen=True, slots=True)
class Outcome:
    """What :func:`run_model` returns: the synthesis's ``summary()`` (``None`` when it
    failed), the status, the error line (``None`` when solved) and the wall seconds."""

    summary: dict[str, Any] | None
    status: str
    error: str | None
    wall_seconds: float


def run_model(load: Callable[[], Model], settings: Settings,
              constraints: tuple[str, ...] = (), then: str | None = None, *,
              whole: bool = False) -> Outcome:
    """Load a model with ``load()`` and solve the problem it poses with ``settings``,
    ``constraints`` (after the model's own) and ``then`` (:func:`mitld_lp.synthesis.pose`:
    every route, the constrained one included); every failure but an interrupt becomes
    an :class:`Outcome` with its status.  ``whole``: the model file's ``[budgets]
    time_limit`` counts from the start of the load, as ``--time-limit`` does (a batch's
    model), not from the solve's (a sweep's point)."""
    from dataclasses import replace

    from mitld_lp.synthesis import pose, solve

    start = time.perf_counter()
    try:
        model = load()
        limit = model.budgets.get("time_limit")
        if whole and settings.time_limit is None and limit is not None:
            settings = replace(settings, time_limit=max(
                limit - (time.perf_counter() - start), 0.0))
        summary = solve(pose(model, constraints, then=then, settings=settings)).summary()
    except Exception as exc:  # noqa: BLE001 - a point's failure is its record
        status, message = classify(exc)
        return Outcome(None, status, message, time.perf_counter() - start)
    return Outcome(summary, str(summary["status"]), None, time.perf_counter() - start)


def record(outcome: Outcome) -> dict[str, Any]:
    """The result columns of an outcome (:data:`RESULT_COLUMNS`)."""
    out: dict[str, Any] = dict.fromkeys(RESULT_COLUMNS)
    out.update(status=outcome.status, error=outcome.error, certified=False,
               wall_seconds=outcome.wall_seconds)
    s = outcome.summary
    if s is not None:
        for k in ("certified", "lower", "upper", "value", "epsilon_achieved", "dta_states",
                  "states", "choices", "transitions", "seconds"):
            out[k] = RESULT_COLUMNS[k](s[k])
        timings = s.get("timings", {})
        for stage in _STAGES:
            if stage in timings:
                out[f"seconds_{stage}"] = float(timings[stage])
    return out


@dataclass(frozen=True, slots=True)
class PointTask:
    """One point to solve: its model file's text, the path its relative names are
    resolved from (the base model file), and the settings."""

    index: int
    model_text: str
    source: str
    settings: Settings


def solve_point(task: PointTask) -> dict[str, Any]:
    """The result columns of one point (runs in a worker process or a Dask task)."""
    from mitld_lp.model import loads_model

    return record(run_model(lambda: loads_model(task.model_text, task.source,
                                               max_states=task.settings.max_states,
                                               max_memory=task.settings.max_memory),
                            task.settings))


def failed(status: str, message: str) -> dict[str, Any]:
    """The result columns of a point that gave no outcome (its worker was lost)."""
    return record(Outcome(None, status, printable(message.splitlines()[0] if message else ""),
                          0.0))
