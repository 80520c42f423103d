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

__all__ = ["Status", "LPResult", "IterationResult", "Lifted", "LIFT_AT_READ", "entry", "held",
           "lifted", "read_only"]

#: Whether the solvers' records hold their per-state vectors on the quotient and lift
#: them at each read (:class:`Lifted`, the default); False: lifted when the record is
#: made and held so (the eager records, the same bits: what the tests compare against).
LIFT_AT_READ = True


def read_only(a: np.ndarray) -> np.ndarray:
    """``a`` as an array that refuses writes (how records hand out their arrays)."""
    a = np.asarray(a)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, slots=True, eq=False)
class Lifted:
    """A vector of the product's states held as its quotient's (``reduced``, a float a
    reduced state) and lifted at each read (:meth:`lift`): what a solver's record keeps
    of its values and bounds, so that a solve that reads them only on the quotient (the
    LP's bounds) or not at all never makes the product's vector, and the records hold a
    float a reduced state through the certificates, not one a product state.

    The lift is :meth:`mitld_lp.solvers.reduced.Quotient.lift`'s gather: a state reads
    its reduced state's value, a removed one (``state_map < 0``) its qualitative value
    (1 on ``one``, else 0); ``forced``: every state of ``one`` set to 1 after it (the
    interval iteration's rule: kept or removed, such a state has the bracket [1, 1]),
    ``kept_forced`` whether that writes anything (a kept state of ``one``; the plain
    route's quotients keep none).  ``state_map`` and ``one`` are the quotient's own
    arrays (shared, not copied: they outlive the quotient's matrix, a few bytes a state
    against the eight of each lifted vector)."""

    reduced: np.ndarray
    state_map: np.ndarray
    one: np.ndarray
    forced: bool = False
    kept_forced: bool = False

    @staticmethod
    def of(reduced: np.ndarray, state_map: np.ndarray, one: np.ndarray,
           forced: bool = False, *, kept: bool | None = None) -> Lifted:
        """``reduced`` (float64, read-only) to be lifted by ``state_map`` and ``one``;
        ``forced``: every state of ``one`` set to 1 after the gather (``kept``: whether
        the quotient keeps such a state, where the caller knows; else looked up).  A
        view into another array is copied, C-contiguous: the record would hold the
        rest of it, and a strided vector is another type to a compiled kernel that
        reads it (a compile in a solve)."""
        values = np.asarray(reduced, dtype=np.float64)
        if values.base is not None or not values.flags.c_contiguous:
            values = values.copy()
        one = np.asarray(one, dtype=bool)
        if kept is None:
            kept = forced and values.size > 0 and bool(np.any(one & (state_map >= 0)))
        return Lifted(read_only(values), state_map, one, forced, forced and kept)

    def lift(self) -> np.ndarray:
        """The product's vector, a fresh read-only array at each call (to the bit the
        eager lift's: the same gather, the same writes)."""
        values = self.reduced
        if values.size == 0:  # nothing kept: every state is of value 1 or 0
            out = np.where(self.one, 1.0, 0.0)
        else:  # a removed state (-1) reads the last value and is overwritten
            out = values[self.state_map]
            np.copyto(out, self.one, where=self.state_map < 0)
            if self.kept_forced:  # a removed state of ``one`` has its 1 already
                out[self.one] = 1.0
        return read_only(out)

    def __getitem__(self, index: np.ndarray | slice) -> np.ndarray:
        """``self.lift()[index]`` (an index array, a mask or a slice of the product's
        states), gathered for those states alone: the same floats.  A mask is turned
        into its states once (not applied to the state map and to ``one`` apart), and
        ``one`` is read only where it writes: at removed states, or where a kept state
        is forced to 1 (the certificate's two reads on QVBS ``zeroconf`` 1000-4, 164,171
        and 87,155 of 301,219 states: 1.0 and 1.3 ms down to 0.6 and 0.7)."""
        if isinstance(index, np.ndarray) and index.dtype == np.bool_:
            index = np.flatnonzero(index)
        sm = self.state_map[index]
        if self.reduced.size == 0:
            return np.where(self.one[index], 1.0, 0.0)
        out = self.reduced[sm]
        removed = sm < 0
        if self.kept_forced:
            one = self.one[index]
            np.copyto(out, one, where=removed)
            out[one] = 1.0
        elif removed.any():
            np.copyto(out, self.one[index], where=removed)
        return out

    def at(self, state: int) -> float:
        """The lifted vector's entry at ``state`` (no vector made)."""
        r = int(self.state_map[state])
        if r < 0 or self.reduced.size == 0 or (self.forced and self.one[state]):
            return 1.0 if self.one[state] else 0.0
        return float(self.reduced[r])

    def on(self, state_map: np.ndarray) -> np.ndarray | None:
        """The reduced vector, where every product state of a reduced state reads it
        (lifted by the quotient's own ``state_map``, no kept state forced to 1): what
        the lifted vector gathered at any member of each reduced state gives, to the
        bit; else None (read the lifted vector)."""
        if state_map is not self.state_map or self.reduced.size == 0 or self.kept_forced:
            return None
        return self.reduced

    @property
    def shape(self) -> tuple[int, ...]:
        return self.state_map.shape


def held(reduced: np.ndarray, state_map: np.ndarray, one: np.ndarray,
         forced: bool = False, *, kept: bool | None = None) -> np.ndarray | Lifted:
    """A record's vector of the quotient's values ``reduced`` (:meth:`Lifted.of`): held
    so and lifted at each read, or lifted now where :data:`LIFT_AT_READ` is False."""
    v = Lifted.of(reduced, state_map, one, forced, kept=kept)
    return v if LIFT_AT_READ else v.lift()


def entry(v: np.ndarray | Lifted, state: int) -> float:
    """The product's vector ``v`` (held or lifted) at ``state``."""
    return v.at(state) if isinstance(v, Lifted) else float(v[state])


def lifted(v: np.ndarray | Lifted | None) -> np.ndarray | None:
    """``v`` as the product's vector (a :class:`Lifted` lifted, an array or None as
    they are)."""
    return v.lift() if isinstance(v, Lifted) else v


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
            ``None`` without a solution.  Held on the quotient (``held_values``, a
            :class:`Lifted`) and lifted at each read: a fresh read-only array.
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
    held_values: np.ndarray | Lifted | None
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

    @property
    def values(self) -> np.ndarray | None:
        """The value function on the product's states (class docs), lifted now."""
        return lifted(self.held_values)


@dataclass(frozen=True, slots=True, eq=False)
class IterationResult:
    """The answer of :func:`mitld_lp.solvers.interval_iteration`.

    Attributes:
        status: ``OPTIMAL`` when the stopping gap fell under the tolerance,
            ``MAX_ITERATIONS`` otherwise (the bracket is still valid).
        lower, upper: ``(n_states,)`` sound bounds on the optimal reach probability of
            every state (``lower <= Pmax <= upper``): held on the quotient
            (``held_lower``, ``held_upper``, each a :class:`Lifted`) and lifted at each
            read, a fresh read-only array (keep it where it is read often).
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
    held_lower: np.ndarray | Lifted
    held_upper: np.ndarray | Lifted
    value_lower: float
    value_upper: float
    iterations: int
    seconds: float
    greedy: np.ndarray | Callable[[], np.ndarray] | None
    message: str

    @property
    def lower(self) -> np.ndarray:
        """The lower bounds on the product's states (class docs), lifted now."""
        return lifted(self.held_lower)

    @property
    def upper(self) -> np.ndarray:
        """The upper bounds on the product's states (class docs), lifted now."""
        return lifted(self.held_upper)

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
