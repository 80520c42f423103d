r"""The expected total reward until a target in floating point, with a bracket that holds
in exact arithmetic: Storm's ``R{"r"}min=? [F target]`` and ``R{"r"}max=? [F target]``
on a model built in doubles (:func:`mitld_lp.worlds.prism_rewards.reward_mdp` with
``exact=False``), the default of the door; the rational answer is
:mod:`mitld_lp.exact.reward` (``--exact``).

Infinity is decided by the graph as there (:func:`mitld_lp.exact.reward.almost_sure`:
``Rmin`` is infinite where no scheduler reaches the target almost surely, ``Rmax`` where
some scheduler misses it with positive probability); the finite values are found and
bounded on the states that remain, with the *useful* choices only (those whose
successors all have finite values).

**The policy.**  The occupancy LP (Clarabel, up to :data:`LP_MAX_CHOICES` useful
choices): the expected visits ``y >= 0`` of each choice from the initial state, flow
``sum_c y(c) - sum_c' P(c', s) y(c') = [s = init]`` per state, objective ``r . y``
minimised (``Rmin``) or maximised (``Rmax``); its policy is each visited state's most
used choice.  States it does not visit, and states whose LP choice does not reach the
target almost surely (a circulation in a zero-reward end component), take the
attractor's choice (one layer closer to the target).  Float policy iteration (sparse LU
of each policy's chain) then improves the policy on every state where a choice is
better by more than the float noise; the LP's objective is kept as a cross-check.

**The bracket.**  From the last policy's float values ``v`` and ``w``, the chain's
accumulated ``1 + v`` (one more solve with the same LU), the candidates are
``v -/+ delta w`` with ``delta`` twice the measured relative residual; each side is then
*checked* with every float sum bounded below or above in exact arithmetic
(:mod:`mitld_lp.solvers.rounding`: the stored probabilities and rewards are within
``ETA`` of the file's, relatively), and where a state fails, it is moved to what its
choices need and the check repeated (at most :data:`REPAIR_SWEEPS` sweeps):

* ``Rmin``, lower: ``L(s) <= r(c) + P_c L`` for *every* useful choice: a sub-solution;
  unrolled along any scheduler that reaches the target almost surely it gives
  ``L <= `` its expected reward, so ``L <= Rmin``.  The zero-reward maximal end
  components (of the useful choices) hold ``L`` constant (the least over each), so
  their internal choices pass as convex combinations;
* ``Rmin``, upper: ``U(s) >= r(c) + P_c U`` for the policy's choice ``c``: a
  super-solution of its chain, so ``U >= `` the policy's value (its least fixed
  point), which is finite and ``>= Rmin`` because the policy reaches the target almost
  surely (checked on its chain's graph);
* ``Rmax``, upper: ``U(s) >= r(c) + P_c U`` for every choice: a pre-fixed point of the
  Bellman operator, above its least fixed point ``Rmax``;
* ``Rmax``, lower: ``L(s) <= r(c) + P_c L`` for the policy's choice: below the policy's
  value (every scheduler reaches the target almost surely there), so ``L <= Rmax``.

A side that still fails after the sweeps falls back to what always holds (``0`` below;
nothing above, so the answer is not certified and says so).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.certify_chain import RowModel
from mitld_lp.solvers.clarabel_lp import clarabel_has_faer, solve_clarabel
from mitld_lp.solvers.graph import maximal_end_components
from mitld_lp.solvers.reward_graph import almost_sure, attractor_policy, keeps_inside
from mitld_lp.solvers.rounding import ETA, UNIT, above, below, rounding
from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["LP_MAX_CHOICES", "REPAIR_SWEEPS", "RewardBracket", "solve_reward_float"]

log = logging.getLogger(__name__)

LP_MAX_CHOICES = 20_000
"""The useful choices up to which the occupancy LP gives the first policy (past it the
attractor's policy, or any choice for ``Rmax``, starts the policy iteration)."""

REPAIR_SWEEPS = 200
"""The sweeps a side's check may move failing states before it falls back."""

MAX_ROUNDS = 100
"""Policy-iteration rounds at most (each one sparse LU of the policy's chain)."""


@dataclass(frozen=True, slots=True)
class RewardBracket:
    """The answer at the initial state: ``lower <= value <= upper`` (``inf`` both when the
    graph decides infinity; ``upper`` is ``inf`` when not certified), ``certified``,
    the policy (a choice per state, -1 where it does not matter), the policy-iteration
    rounds, the LP's objective (None when the LP was not run) and status."""

    lower: float
    upper: float
    infinite: bool
    certified: bool
    policy: np.ndarray
    rounds: int
    lp_value: float | None
    lp_status: str
    sweeps: int

    @property
    def value(self) -> float:
        """The midpoint of the bracket (``inf`` for infinity)."""
        return self.lower if self.infinite else (self.lower + self.upper) / 2


class _Rows:
    """The useful choices as a CSR matrix over all states, with their float rewards and
    the rounding of their sums."""

    def __init__(self, model: RewardMDP, useful: np.ndarray, eta: float) -> None:
        self.n = model.n_states
        self.rows = np.flatnonzero(useful)
        self.position = np.full(useful.size, -1, dtype=np.int64)
        self.position[self.rows] = np.arange(self.rows.size)
        full = sp.csr_array((np.asarray(model.probabilities, dtype=np.float64),
                             model.indices, model.indptr),
                            shape=(model.indptr.size - 1, self.n))
        self.matrix = sp.csr_array(full[self.rows])
        self.owner = model.owner[self.rows]
        self.states, self.starts = np.unique(self.owner, return_index=True)
        reward = np.asarray(model.rewards, dtype=np.float64)[self.rows]
        self.reward = reward
        self.r_low = reward * (1.0 - 2.0 * ETA)
        self.r_high = reward * (1.0 + 2.0 * ETA)
        self.rnd = rounding(self.matrix, eta)
        self.zero = reward == 0.0
        self.every = np.arange(self.rows.size)
        self.nonempty = np.diff(self.matrix.indptr) > 0

    def _support(self, x: np.ndarray, largest: bool) -> np.ndarray:
        out = np.full(self.rows.size, -np.inf if largest else np.inf)
        ufunc = np.maximum if largest else np.minimum
        if self.matrix.indices.size:
            out[self.nonempty] = ufunc.reduceat(x[self.matrix.indices],
                                                self.matrix.indptr[:-1][self.nonempty])
        return out

    def low(self, x: np.ndarray) -> np.ndarray:
        """Per row, a number at most the exact ``r(c) + P_c x`` (``x >= 0``)."""
        sums = below(self.rnd, self.every, self.matrix @ x)
        bound = (self.r_low + sums) * (1.0 - 4.0 * UNIT)
        return np.maximum(bound, self._support(x, largest=False))  # r >= 0: a mean

    def high(self, x: np.ndarray) -> np.ndarray:
        """Per row, a number at least the exact ``r(c) + P_c x`` (``x >= 0``)."""
        sums = above(self.rnd, self.every, self.matrix @ x)
        bound = (self.r_high + sums) * (1.0 + 4.0 * UNIT)
        return np.where(self.zero, np.minimum(bound, self._support(x, largest=True)), bound)

    def per_state(self, values: np.ndarray, sense: str) -> np.ndarray:
        """Per state of :attr:`states`: the least (``min``) or greatest of its rows'."""
        ufunc = np.minimum if sense == "min" else np.maximum
        return ufunc.reduceat(values, self.starts)


def _zero_mecs(model: RewardMDP, rows: _Rows) -> np.ndarray:
    """The zero-reward maximal end component of each state (-1 in none), over the useful
    choices of reward 0."""
    keep = rows.rows[rows.zero]
    if not keep.size:
        return np.full(model.n_states, -1, dtype=np.int64)
    matrix = sp.csr_array(rows.matrix[np.flatnonzero(rows.zero)])
    counts = np.bincount(model.owner[keep], minlength=model.n_states)
    groups = np.concatenate(([0], np.cumsum(counts)))
    found = maximal_end_components(RowModel(matrix, groups, model.initial),
                                   counts > 0)
    return np.asarray(found.mec_of, dtype=np.int64)


def _sync(x: np.ndarray, mec: np.ndarray) -> None:
    """``x`` set, on each zero-reward end component, to its least value there."""
    inside = mec >= 0
    if inside.any():
        least = np.full(int(mec.max()) + 1, np.inf)
        np.minimum.at(least, mec[inside], x[inside])
        x[inside] = least[mec[inside]]


class _Chain:
    """A policy's chain on the solved states: its LU, values and accumulated ``1 + v``."""

    def __init__(self, rows: _Rows, policy_rows: np.ndarray, solved: np.ndarray) -> None:
        from scipy.sparse.linalg import splu

        n = rows.n
        local = np.full(n, -1, dtype=np.int64)
        local[solved] = np.arange(solved.size)
        p = sp.csr_array(rows.matrix[policy_rows])
        coo = p.tocoo()
        keep = local[coo.col] >= 0
        a = sp.identity(solved.size, format="csc") - sp.csc_array(
            (coo.data[keep], (coo.row[keep], local[coo.col[keep]])),
            shape=(solved.size, solved.size))
        lu = splu(sp.csc_matrix(a))
        self.v = np.zeros(n)
        self.v[solved] = np.maximum(lu.solve(rows.reward[policy_rows]), 0.0)
        residual = rows.reward[policy_rows] + p @ self.v - self.v[solved]
        self.delta = 2.0 * float(np.max(np.abs(residual) / (1.0 + self.v[solved]),
                                        initial=0.0)) + 64.0 * ETA
        self.w = np.zeros(n)
        self.w[solved] = np.maximum(lu.solve(1.0 + self.v[solved]), 0.0)


def _occupancy(rows: _Rows, model: RewardMDP, solved: np.ndarray, sense: str
               ) -> tuple[np.ndarray | None, float | None, str]:
    """The occupancy LP's most used choice per visited state (-1 elsewhere), its
    objective and Clarabel's status."""
    m, k = solved.size, rows.rows.size
    local = np.full(rows.n, -1, dtype=np.int64)
    local[solved] = np.arange(m)
    coo = rows.matrix.tocoo()
    keep = local[coo.col] >= 0
    flow = (sp.csc_array((np.ones(k), (local[rows.owner], np.arange(k))), shape=(m, k))
            - sp.csc_array((coo.data[keep], (local[coo.col[keep]], coo.row[keep])),
                           shape=(m, k)))
    a = sp.csc_array(sp.vstack([flow, -sp.identity(k, format="csc")]))
    b = np.zeros(m + k)
    b[local[model.initial]] = 1.0
    q = rows.reward if sense == "min" else -rows.reward
    settings: dict[str, object] = {"iterative_refinement_enable": False}  # polished
    if clarabel_has_faer():  # as the probabilities' LP when policy iteration follows
        settings.update(direct_solve_method="faer", max_threads=1)
    answer = solve_clarabel(q, a, b, zero=m, nonneg=k, settings=settings)
    if answer.x is None:
        return None, None, answer.status.value
    y = answer.x
    visits = np.add.reduceat(y, rows.starts)
    best = rows.starts + np.asarray([int(np.argmax(y[a:b])) for a, b in
                                     zip(rows.starts, np.append(rows.starts[1:], k),
                                         strict=True)], dtype=np.int64)
    policy = np.full(rows.n, -1, dtype=np.int64)
    seen = visits > 1e-7
    policy[rows.states[seen]] = rows.rows[best[seen]]
    value = float(rows.reward @ np.maximum(y, 0.0))
    return policy, value, answer.status.value


def _proper(model: RewardMDP, policy: np.ndarray) -> np.ndarray:
    """The states from which the policy's chain reaches the target almost surely (a
    state without a choice, -1, stays put)."""
    n = model.n_states
    chosen = np.where(policy >= 0, policy, -1)
    starts = np.where(chosen >= 0, model.indptr[np.maximum(chosen, 0)], 0)
    ends = np.where(chosen >= 0, model.indptr[np.maximum(chosen, 0) + 1], 0)
    counts = np.where(chosen >= 0, ends - starts, 1)
    indptr = np.concatenate(([0], np.cumsum(counts)))
    indices = np.empty(int(indptr[-1]), dtype=np.int64)
    for s in np.flatnonzero(chosen < 0):
        indices[indptr[s]] = s
    picked = np.flatnonzero(chosen >= 0)
    if picked.size:
        spans = np.concatenate([np.arange(a, b) for a, b in
                                zip(starts[picked], ends[picked], strict=True)])
        where = np.concatenate([np.arange(indptr[s], indptr[s + 1]) for s in picked])
        indices[where] = model.indices[spans]
    chain = RewardMDP(groups=np.arange(n + 1), indptr=indptr, indices=indices,
                      probabilities=(), rewards=(), target=model.target,
                      initial=model.initial)
    return almost_sure(chain, "max")


def _improve(rows: _Rows, policy: np.ndarray, v: np.ndarray, sense: str) -> int:
    """Each state switched to its best choice where it beats the policy's by more than
    the float noise; the number of switches."""
    q = rows.reward + rows.matrix @ v
    noise = 1e-10 * (1.0 + np.abs(v[rows.owner]))
    gain = (v[rows.owner] - q) if sense == "min" else (q - v[rows.owner])
    gain = np.where(gain > noise, gain, -np.inf)
    best = np.maximum.reduceat(gain, rows.starts)
    moving = np.flatnonzero(best > -np.inf)
    if not moving.size:
        return 0
    ends = np.append(rows.starts[1:], rows.rows.size)
    for i in moving.tolist():
        a, b = int(rows.starts[i]), int(ends[i])
        policy[rows.states[i]] = rows.rows[a + int(np.argmax(gain[a:b]))]
    return int(moving.size)


def _check(rows: _Rows, x: np.ndarray, solved: np.ndarray, sense: str, policy_rows:
           np.ndarray | None, lower: bool, mec: np.ndarray | None) -> tuple[bool, int]:
    """Repair sweeps of one side (module docs), ``x`` moved in place; whether it passed
    and the sweeps taken."""
    for sweep in range(REPAIR_SWEEPS + 1):
        values = rows.low(x) if lower else rows.high(x)
        if policy_rows is not None:
            need = np.zeros(rows.n)
            need[solved] = values[policy_rows]
        else:
            need = np.zeros(rows.n)
            need[rows.states] = rows.per_state(values, sense)
        ok = (x[solved] <= need[solved]) if lower else (x[solved] >= need[solved])
        if ok.all():
            return True, sweep
        moved = np.minimum(x, need) if lower else np.maximum(x, need)
        x[solved] = moved[solved]
        if mec is not None:
            _sync(x, mec)
    return False, REPAIR_SWEEPS


def solve_reward_float(model: RewardMDP, sense: str, *, time_limit: float | None = None,
                       use_lp: bool = True, eta: float = ETA) -> RewardBracket:
    """``Rmin`` (``sense`` "min") or ``Rmax`` ("max") of the expected total reward until
    the target, bracketed (module docs).  ``model``'s probabilities and rewards are
    floats (or anything :func:`numpy.asarray` reads as them); ``eta``: the probabilities'
    allowance (:func:`mitld_lp.solvers.rounding.model_eta` for a product)."""
    if sense not in ("min", "max"):
        raise ValueError(f"sense must be 'min' or 'max', got {sense!r}")
    rewards = np.asarray(model.rewards, dtype=np.float64)
    if (rewards < 0).any() or not np.isfinite(rewards).all():
        raise ValueError("expected reward: a negative or non-finite reward (the rewards "
                         "must be finite and >= 0)")
    deadline = time.perf_counter() + (np.inf if time_limit is None else time_limit)
    finite = almost_sure(model, sense)
    owner = model.owner
    none = np.full(model.n_states, -1, dtype=np.int64)
    if not finite[model.initial]:
        return RewardBracket(np.inf, np.inf, True, True, none, 0, None, "not run", 0)
    useful = keeps_inside(model, finite) & finite[owner] & ~model.target[owner]
    solved = np.flatnonzero(finite & ~model.target)
    if not solved.size:  # the initial state is a target
        return RewardBracket(0.0, 0.0, False, True, none, 0, None, "not run", 0)
    rows = _Rows(model, useful, eta)
    start = (attractor_policy(model, finite, useful) if sense == "min" else none.copy())
    if sense == "max":
        start[rows.states] = rows.rows[rows.starts]
    lp_value, lp_status = None, "not run"
    if use_lp and rows.rows.size <= LP_MAX_CHOICES:
        lp_policy, lp_value, lp_status = _occupancy(rows, model, solved, sense)
        if lp_policy is not None:
            policy = np.where(lp_policy >= 0, lp_policy, start)
            bad = ~_proper(model, policy)
            policy[bad] = start[bad]  # a loop of the LP's: the attractor leaves it
            start = policy
    elif use_lp:
        lp_status = f"not run: {rows.rows.size:,} useful choices > {LP_MAX_CHOICES:,}"
    policy = start
    rounds = 0
    while True:
        rounds += 1
        chain = _Chain(rows, rows.position[policy[solved]], solved)
        if rounds >= MAX_ROUNDS or time.perf_counter() > deadline:
            break
        if not _improve(rows, policy, chain.v, sense):
            break
    proper = _proper(model, policy)[solved].all()
    slack = chain.delta * chain.w
    low, high = np.maximum(chain.v - slack, 0.0), chain.v + slack
    low[model.target], high[model.target] = 0.0, 0.0
    mec = _zero_mecs(model, rows) if sense == "min" else None
    if mec is not None:
        _sync(low, mec)
    policy_rows = rows.position[policy[solved]]
    low_ok, low_sweeps = _check(rows, low, solved, sense,
                                None if sense == "min" else policy_rows, True, mec)
    high_ok, high_sweeps = _check(rows, high, solved, sense,
                                  policy_rows if sense == "min" else None, False, None)
    if not low_ok:
        log.info("expected reward: the lower bound's check failed; 0 holds")
        low[:] = 0.0
    upper = float(high[model.initial]) if high_ok and (proper or sense == "max") else np.inf
    if lp_value is not None:
        log.debug("expected reward: occupancy LP %s, bracket [%r, %r]", lp_value,
                 float(low[model.initial]), upper)
    return RewardBracket(lower=float(low[model.initial]), upper=upper, infinite=False,
                         certified=bool(np.isfinite(upper)), policy=policy, rounds=rounds,
                         lp_value=lp_value, lp_status=lp_status,
                         sweeps=low_sweeps + high_sweeps)
