r"""Every call to Clarabel: one LP in Clarabel's form, its outcome in the solvers' one
status vocabulary (:data:`CLARABEL_STATUS`).

Clarabel solves ``min q'x  s.t.  Ax + s = b, s in K`` with dual ``q + A'z = 0,
z in K*``; here ``K = {0}^zero x R_+^nonneg`` (the equality rows first) and no quadratic
term.  What the rows mean is the caller's business (:mod:`.lp_backends`,
:mod:`.constrained`, :mod:`.robust_lp`).

``AlmostSolved`` (Clarabel met its reduced tolerances only) is ``INACCURATE``: the
solution comes with it, and whether it is good enough is decided by what the caller
proves of it (the certificates check every bound in exact arithmetic), not by its
status.
"""

from __future__ import annotations

import functools
import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.result import Status

__all__ = ["CLARABEL_STATUS", "ClarabelAnswer", "clarabel_has_faer", "is_fatal",
           "solve_clarabel"]

CLARABEL_STATUS = {  # Clarabel's status words (clarabel.SolverStatus) as ours
    "Solved": Status.OPTIMAL,
    "AlmostSolved": Status.INACCURATE,
    "PrimalInfeasible": Status.INFEASIBLE,
    "AlmostPrimalInfeasible": Status.INFEASIBLE,
    "DualInfeasible": Status.UNBOUNDED,
    "AlmostDualInfeasible": Status.UNBOUNDED,
    "MaxIterations": Status.MAX_ITERATIONS,
    "MaxTime": Status.TIME_LIMIT,
    "NumericalError": Status.FAILED,
    "InsufficientProgress": Status.FAILED,
    "CallbackTerminated": Status.FAILED,
    "Unsolved": Status.FAILED,
}
"""Clarabel's status words as :class:`~mitld_lp.solvers.result.Status` (a word not
listed, from a later Clarabel, is ``FAILED``)."""


@dataclass(frozen=True, slots=True, eq=False)
class ClarabelAnswer:
    """What one Clarabel call gave.

    Attributes:
        status: in the solvers' vocabulary (:data:`CLARABEL_STATUS`).
        word: Clarabel's own status word, or the exception it raised / why it was not
            run.
        x: the primal solution (``None`` unless ``status.has_solution``).
        z: the dual solution, one entry per row of ``A`` (``None`` likewise).
        iterations: Clarabel's iteration count (0 if it did not run).
    """

    status: Status
    word: str
    x: np.ndarray | None = None
    z: np.ndarray | None = None
    iterations: int = 0

    @property
    def message(self) -> str:
        """``"clarabel: <word>"``, how a record reports the solver's words."""
        return f"clarabel: {self.word}"


def is_fatal(exc: BaseException) -> bool:
    """Whether ``exc`` must propagate rather than become a ``FAILED`` status."""
    return isinstance(exc, KeyboardInterrupt | SystemExit | GeneratorExit | MemoryError)


def solve_clarabel(q: np.ndarray, a: sp.csc_array, b: np.ndarray, *, zero: int,
                   nonneg: int, settings: Mapping[str, Any]) -> ClarabelAnswer:
    """``min q'x  s.t.  a x + s = b``, the first ``zero`` rows equalities (``s = 0``),
    the next ``nonneg`` rows inequalities (``s >= 0``), by Clarabel with ``settings``
    (its setting names, e.g. ``tol_feas``, ``time_limit``; an unknown one is a ``FAILED``
    answer).  Every failure, an exception inside Clarabel included, is a status."""
    clarabel: Any = importlib.import_module("clarabel")
    n = q.shape[0]
    options = clarabel.DefaultSettings()
    options.verbose = False
    for key, val in settings.items():
        if not hasattr(options, key):
            return ClarabelAnswer(Status.FAILED, f"unknown setting {key!r}")
        setattr(options, key, val)
    cones = ([clarabel.ZeroConeT(zero)] if zero else []) + (
        [clarabel.NonnegativeConeT(nonneg)] if nonneg else [])
    try:
        solution = clarabel.DefaultSolver(sp.csc_matrix((n, n)), q, sp.csc_matrix(a), b,
                                          cones, options).solve()
    except BaseException as exc:  # includes pyo3's PanicException
        if is_fatal(exc):
            raise
        return ClarabelAnswer(Status.FAILED, f"{type(exc).__name__}: {exc}")
    word = str(solution.status)
    status = CLARABEL_STATUS.get(word, Status.FAILED)
    iterations = int(solution.iterations)
    if not status.has_solution:
        return ClarabelAnswer(status, word, iterations=iterations)
    return ClarabelAnswer(status, word, np.asarray(solution.x, dtype=np.float64),
                          np.asarray(solution.z, dtype=np.float64), iterations)


@functools.cache
def clarabel_has_faer() -> bool:
    """Whether the installed Clarabel factorises with faer (a build without it refuses
    the setting when a solver is made, so a one-variable LP is solved once to ask)."""
    answer = solve_clarabel(np.zeros(1), sp.csc_array(-np.eye(1)), np.zeros(1), zero=0,
                            nonneg=1, settings={"direct_solve_method": "faer"})
    return answer.status is not Status.FAILED
