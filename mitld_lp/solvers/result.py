"""Result records of the solvers: a status and named fields, never bare tuples.

A solver never raises on a solver failure (an exception inside cvxpy / Clarabel, a
non-optimal termination, an iteration limit): it returns a record whose ``status`` says
what happened and whose ``message`` carries the solver's own words.  Arrays in a record
are read-only.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass, fields, replace

import numpy as np

__all__ = ["Status", "LPResult", "IterationResult", "read_only"]


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as an array that refuses writes (how records hand out their arrays)."""
    a = np.asarray(a)
    a.setflags(write=False)
    return a


class Status(enum.StrEnum):
    """How a solver terminated: one vocabulary for every route (a ``StrEnum``: each
    member is also its string, ``Status.OPTIMAL == "optimal"``)."""

    OPTIMAL = "optimal"
    """Solved to the requested tolerance."""
    INACCURATE = "inaccurate"
    """The solver returned a solution but could not reach the requested tolerance."""
    INFEASIBLE = "infeasible"
    UNBOUNDED = "unbounded"
    MAX_ITERATIONS = "max_iterations"
    """Stopped at the iteration limit; interval iteration still returns a valid bracket."""
    TIME_LIMIT = "time_limit"
    FAILED = "failed"
    """The solver could not be run or broke down (see the message)."""

    @property
    def has_solution(self) -> bool:
        """Whether the record carries a (possibly inaccurate) solution."""
        return self in (Status.OPTIMAL, Status.INACCURATE)


@dataclass(frozen=True, slots=True, eq=False)
class LPResult:
    """The answer of :func:`mitld_lp.solvers.solve_lp`.

    Attributes:
        status: how the solve ended.
        message: the solver's own words (or why no solver was needed / could be run).
        value: the optimal reach probability at ``mdp.initial`` (``nan`` without solution).
        values: ``(n_states,)`` the value function read from the LP duals (target states
            1, prob-0 states 0, members of a collapsed MEC the MEC's value), clipped to
            [0, 1] (clipping keeps a dual-feasible vector dual feasible).  Exact on the
            states the optimal occupancy visits; elsewhere an upper bound (any dual
            feasible vector is), unless the LP was solved with ``everywhere=True``.
            ``None`` without a solution.
        primal_objective: ``sum_c y(c) P(c, target)`` at the returned occupancy;
            ``nan`` without a solution and where the occupancy was not made
            (``solve_lp(..., primal=False)``: a two-model solve's bound model).
        dual_objective: ``sum_s b(s) v(s)`` at the returned duals.
        occupancy: ``(n_choices,)`` expected number of times each original choice is
            taken (0 for choices not in the LP: MEC-internal, target, prob-0).
            ``None`` without a solution, and where the caller did not ask for the
            flows (``solve_lp(..., flows=False)``: the plain route's models).
        policy: ``(n_states,)`` int64, a deterministic optimal policy: the chosen choice
            row per state, ``-1`` for target and absorbing states.
        randomized: ``(n_choices,)`` the randomised policy of the occupancies: per
            visited state ``y(c) / sum_{c' of s} y(c')``, elsewhere the deterministic
            policy's choice with probability 1 (all zero for states with policy -1).
            ``None`` where ``occupancy`` is.
        solver: the solver's name (``"CLARABEL"``, ``"HIGHS"``, ...), ``""`` if none ran.
        backend: ``"cvxpy"`` or ``"direct"``.
        iterations: the solver's iteration count (0 if unknown or none ran).
        seconds: wall-clock time of the whole call (reduction, solve, extraction).
        lp_shape: ``(rows, columns)`` of the LP's equality constraints (reduced states,
            reduced choices).
    """

    status: Status
    message: str
    value: float
    values: np.ndarray | None
    primal_objective: float
    dual_objective: float
    occupancy: np.ndarray | None
    policy: np.ndarray | None
    randomized: np.ndarray | None
    solver: str
    backend: str
    iterations: int
    seconds: float
    lp_shape: tuple[int, int]


@dataclass(frozen=True, slots=True, eq=False)
class IterationResult:
    """The answer of :func:`mitld_lp.solvers.interval_iteration`.

    Attributes:
        status: ``OPTIMAL`` when the stopping gap fell under the tolerance,
            ``MAX_ITERATIONS`` otherwise (the bracket is still valid).
        lower, upper: ``(n_states,)`` sound bounds on the optimal reach probability of
            every state (``lower <= Pmax <= upper``).
        value_lower, value_upper: the bounds at ``mdp.initial``.
        iterations: Bellman updates performed.
        seconds: wall-clock time of the whole call.
        greedy: the policy (:attr:`policy`) or how to make it: a function of no
            argument, called at the first read of :attr:`policy` (a solve whose LP
            returns a policy never reads the iteration's), or ``None`` once
            :meth:`without_greedy` has let it go unread.
        message: a human-readable summary (the final gap).
    """

    status: Status
    lower: np.ndarray
    upper: np.ndarray
    value_lower: float
    value_upper: float
    iterations: int
    seconds: float
    greedy: np.ndarray | Callable[[], np.ndarray] | None
    message: str

    @property
    def policy(self) -> np.ndarray:
        """``(n_states,)`` int64, the greedy policy on the bound a greedy policy's value
        lies beyond (a maximum's ``lower``, a minimum's ``upper``), lifted through the
        MEC quotient (so it never stays in an end component forever); ``-1`` for target
        and absorbing states.  Made at the first read, then kept (read-only)."""
        made = self.greedy
        if made is None:
            raise AttributeError(
                "IterationResult.policy was not kept: the solve let the iteration's "
                "policy go unread with its quotient (it certified the LP's policy); "
                "mitld_lp.solvers.interval_iteration gives a result that keeps it")
        if callable(made):
            made = read_only(made())
            object.__setattr__(self, "greedy", made)  # a cache: the same record after
        return made

    def without_greedy(self) -> IterationResult:
        """This record without what its policy would be made from, unless it was read
        already (the function holds the reduction the policy is greedy on: a solve that
        releases its quotient drops it this way)."""
        return self if not callable(self.greedy) else replace(self, greedy=None)

    def __getstate__(self) -> list[object]:
        """The fields, the policy made (a function does not pickle)."""
        if callable(self.greedy):
            self.policy  # noqa: B018 - made and kept
        return [getattr(self, f.name) for f in fields(self)]

    def __setstate__(self, state: list[object]) -> None:
        for f, v in zip(fields(self), state, strict=True):
            object.__setattr__(self, f.name, v)
