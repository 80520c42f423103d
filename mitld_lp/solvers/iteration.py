r"""Interval iteration for maximal reachability, and exact evaluation of a policy.

Interval iteration (Haddad & Monmege, TCS 2018; Baier et al., CAV 2017) runs the
Bellman operator

.. math::

    (T x)(s) = \max_{c \in \mathit{Act}(s)} \hat P(c, \mathit{target})
               + \sum_{s'} \hat P(c, s')\, x(s')

on the MEC quotient (:func:`mitld_lp.solvers.quotient.reduce`) from two starting
points: ``x = 0`` (increases to the optimum from below) and ``x = 1`` on the maybe
states (decreases to it from above; this needs the quotient: on an MDP with end
components the upper sequence can get stuck above the optimum).  Both vectors are
updated together with one sparse product and a segmented maximum.

**Topological order** (``topological=True``, the default; this is how Storm's sound
check works): the quotient's strongly connected components are solved level by level,
downstream first (:mod:`mitld_lp.solvers.topological`).  A single-state component is
solved exactly from the bounds downstream (lower from lower, upper from upper); the
non-trivial components of a level are iterated on their own until their gap is below
``tol``, with the bounds downstream as constants.

A component that drains slowly (an event of hazard 1e-6 leaves it once in a million
steps) would need millions of sweeps.  After ``_SWEEPS_BEFORE_POLICY`` sweeps such a
component is *jumped*: a policy is improved to a fixpoint with exact solves of its
chain, and the candidate bounds it gives are kept only if they prove themselves.  With
``t`` the expected number of steps the policy needs to leave the component and ``e > 0``,
``L = v - e t`` satisfies ``L <= T(L)`` and ``U = w + e t'`` (``w`` from the upper exits)
is kept if ``T(U) <= U``.  On a quotient (no end components) ``x <= T(x)`` implies
``x <= Pmax`` and ``T(x) <= x`` implies ``x >= Pmax``, so the checks (done in extended
precision, then rounded outwards) make the jump as sound as a sweep.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse import csgraph
from tqdm.auto import tqdm

from mitld_lp import defaults
from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.quotient import (
    Quotient,
    backward_reachable,
    greedy_choices,
    lift_policy,
    quotient_for,
    segmented_argmax,
)
from mitld_lp.solvers.result import IterationResult, Status, read_only
from mitld_lp.solvers.topological import (
    Block,
    blocks,
    improve_policy,
    solve_chain,
    solve_single_states,
    state_graph,
)

__all__ = ["interval_iteration", "evaluate_policy"]

logger = logging.getLogger(__name__)

_PROGRESS_MIN_STATES = 10_000
"""Below this many reduced states no progress bar is shown (the run is instant)."""

_SWEEPS_BEFORE_POLICY = 100
"""Sweeps of a component before it is jumped by policy evaluation (module docs)."""



@dataclass(slots=True)
class _Budget:
    """Sweeps and seconds left for one call (mutable: shared by every component)."""

    max_iterations: int
    deadline: float
    iterations: int = 0
    stopped: Status | None = field(default=None)

    def spend(self) -> bool:
        """Count one sweep; ``False`` (and the reason in ``stopped``) once out of budget."""
        if self.iterations >= self.max_iterations:
            self.stopped = Status.MAX_ITERATIONS
            return False
        if self.iterations % 16 == 0 and time.perf_counter() >= self.deadline:
            self.stopped = Status.TIME_LIMIT
            return False
        self.iterations += 1
        return True


def _sweeps(block: Block, lo: np.ndarray, hi: np.ndarray, tol: float, budget: _Budget,
            width: Literal["initial", "max"], initial: int, bar: tqdm,
            limit: int | None = None) -> bool:
    """Iterate the block's bounds (``lo``, ``hi`` at ``block.states``) in place until
    the gap is below ``tol`` (at ``initial`` or over the block); ``False`` if the budget
    or ``limit`` sweeps ran out first."""
    exit2 = block.exits(lo, hi)
    local = np.column_stack([lo[block.states], hi[block.states]])

    def gap() -> float:
        if width == "initial" and initial >= 0:
            return float(local[initial, 1] - local[initial, 0])
        return float(np.max(local[:, 1] - local[:, 0], initial=0.0))

    done = 0
    try:
        while gap() >= tol:
            if (limit is not None and done >= limit) or not budget.spend():
                return False
            local = np.maximum.reduceat(block.inner @ local + exit2, block.starts, axis=0)
            done += 1
            if done % 100 == 0:
                bar.update(100)
        return True
    finally:
        lo[block.states], hi[block.states] = local[:, 0], local[:, 1]


def _jump(block: Block, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    """Try the verified policy jump of the module docs on ``block``; update ``lo`` and
    ``hi`` where it proves better bounds.  ``True`` if both bounds were proven."""
    exit2 = block.exits(lo, hi)
    groups = np.append(block.starts, block.choices.shape[0])
    local = np.column_stack([lo[block.states], hi[block.states]])
    start = segmented_argmax(exit2[:, 0] + block.inner @ local[:, 0], groups)
    chosen, v, t = improve_policy(block, exit2[:, 0], start)
    eps = (tol / 4.0) / float(np.max(t))
    lower = v - eps * t
    inner_ld = block.inner.astype(np.longdouble)
    lower_ok = bool(np.all(exit2[chosen, 0] + (inner_ld @ lower)[chosen] >= lower))
    chosen_hi, w, _ = improve_policy(block, exit2[:, 1], chosen)
    # The shift must cover the slowest of the (nearly) optimal choices, not only the
    # policy's: t_hi = 1 + max over choices within tol/4 of optimal of P t_hi.
    owner_w = np.repeat(w, np.diff(groups))
    tied = (owner_w - (exit2[:, 1] + inner_ld @ w)) < tol / 4.0
    _, t_hi, _ = improve_policy(block, np.ones(block.choices.shape[0]), chosen_hi, tied)
    eps_hi = (tol / 4.0) / float(np.max(t_hi))
    upper = w + eps_hi * t_hi
    image = exit2[:, 1] + inner_ld @ upper
    excess = float(np.max(image - np.repeat(upper, np.diff(groups))))
    upper_ok = excess <= 0.0
    if lower_ok:
        low64 = np.nextafter(lower.astype(np.float64), -np.inf)
        local[:, 0] = np.maximum(local[:, 0], np.clip(low64, 0.0, 1.0))
    if upper_ok:
        up64 = np.nextafter(upper.astype(np.float64), np.inf)
        local[:, 1] = np.minimum(local[:, 1], np.clip(up64, 0.0, 1.0))
    lo[block.states], hi[block.states] = local[:, 0], local[:, 1]
    logger.debug("policy jump on %d states: lower %s, upper %s (T(U) - U <= %.1e)",
                 block.states.size, lower_ok, upper_ok, excess)
    return lower_ok and upper_ok


def _topological(q: Quotient, lo: np.ndarray, hi: np.ndarray, tol: float,
                 budget: _Budget, bar: tqdm, *, from_initial: bool) -> None:
    """Fill ``lo`` and ``hi`` level by level (module docs); stops early out of budget.
    ``from_initial``: only the states the initial state can reach (their successors are
    reachable too, so nothing they need is skipped); the others keep ``[0, 1]``."""
    blk = blocks(q)
    wanted = None
    if from_initial:
        order = csgraph.breadth_first_order(state_graph(q), q.initial, directed=True,
                                            return_predecessors=False)
        wanted = np.zeros(q.n_states, dtype=bool)
        wanted[np.asarray(order)] = True
    for level in range(blk.n_levels):
        states = blk.states_at(level)
        if wanted is not None:
            states = states[wanted[states]]
        single = blk.single(states)
        solve_single_states(q, blk, states[single], lo)
        solve_single_states(q, blk, states[single], hi)
        rest = states[~single]
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        if _sweeps(block, lo, hi, tol, budget, "max", -1, bar, _SWEEPS_BEFORE_POLICY):
            continue
        if (budget.stopped is None and _jump(block, lo, hi, tol)
                and float(np.max(hi[rest] - lo[rest])) < tol):
            continue
        if not _sweeps(block, lo, hi, tol, budget, "max", -1, bar):
            return


def interval_iteration(
    mdp: MDP,
    target: np.ndarray,
    *,
    quotient: Quotient | None = None,
    tol: float = defaults.TOL,
    max_iterations: int = 1_000_000,
    progress: bool = True,
    gap: Literal["initial", "max"] = "initial",
    topological: bool = True,
    time_limit: float | None = None,
) -> IterationResult:
    """Sound bounds ``lower <= Pmax(F target) <= upper`` on every state.

    ``topological=False`` sweeps the whole quotient at once and stops when the gap
    ``upper - lower`` is below ``tol`` at the initial state (``gap="initial"``, the
    default) or at every state (``gap="max"``).  ``topological=True`` (module docs)
    brings every component below ``tol`` in turn: with ``gap="initial"`` every one the
    initial state can reach, with ``gap="max"`` all of them.  Either way the bounds are
    valid everywhere, and if the initial state is decided by the graph analysis (target
    or prob-0) no iteration is needed with ``gap="initial"``.  ``max_iterations``
    counts sweeps (over all components); reaching it gives status ``MAX_ITERATIONS``,
    reaching ``time_limit`` seconds ``TIME_LIMIT``, both with the bracket so far
    (``[0, 1]`` where nothing was done).
    ``quotient``: ``reduce(mdp, target)`` if the caller already has it.
    """
    start = time.perf_counter()
    q = quotient_for(mdp, target, quotient)
    n = q.n_states
    lo, hi = np.zeros(n), np.where(q.zero, 0.0, 1.0)
    budget = _Budget(max_iterations,
                     start + time_limit if time_limit is not None else np.inf)
    bar = tqdm(
        total=None, desc="interval iteration", unit="it", leave=False,
        disable=not progress or n < _PROGRESS_MIN_STATES,
    )
    decided = gap == "initial" and q.initial < 0
    try:
        if n and not decided:
            if topological:
                _topological(q, lo, hi, tol, budget, bar, from_initial=gap == "initial")
            else:
                _sweeps(Block.of(q, np.arange(n)), lo, hi, tol, budget, gap, q.initial, bar)
    finally:
        bar.close()
    bounds = np.column_stack([lo, hi])
    np.clip(bounds, 0.0, 1.0, out=bounds)  # rounding can push the upper bound past 1
    width = 0.0 if n == 0 or decided else (
        float(bounds[q.initial, 1] - bounds[q.initial, 0]) if gap == "initial"
        else float(np.max(bounds[:, 1] - bounds[:, 0])))
    status = budget.stopped or (Status.OPTIMAL if width < tol else Status.MAX_ITERATIONS)
    lower = q.lift(bounds[:, 0])
    upper = q.lift(bounds[:, 1])
    policy = lift_policy(mdp, q, greedy_choices(q, bounds[:, 0]) if n else np.zeros(0, int))
    seconds = time.perf_counter() - start
    message = (
        f"gap ({gap}) {width:.3e} {'<' if status == Status.OPTIMAL else '>='} tol {tol:.1e} "
        f"after {budget.iterations} iterations"
        + ("" if budget.stopped is not Status.TIME_LIMIT else f" (time limit {time_limit} s)")
    )
    logger.info("interval iteration: %s, %.3fs", message, seconds)
    return IterationResult(
        status=status,
        lower=read_only(lower),
        upper=read_only(upper),
        value_lower=float(lower[mdp.initial]),
        value_upper=float(upper[mdp.initial]),
        iterations=budget.iterations,
        seconds=seconds,
        policy=read_only(policy),
        message=message,
    )


def evaluate_policy(
    mdp: MDP,
    target: np.ndarray,
    policy: np.ndarray,
    *,
    method: Literal["auto", "direct", "iterative"] = "auto",
    layers: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    r"""The exact probability of reaching ``target`` from every state under ``policy``.

    ``policy[s]`` is the choice row taken in ``s`` (one of ``mdp.choices(s)``), or ``-1``
    in a target state or an absorbing state (a single ``ABSORB`` self-loop), where the
    run stops.  On the induced Markov chain ``P_pi``: target states get 1; states that
    cannot reach the target in the chain's graph get 0 (this makes the rest transient);
    the rest solve the sparse linear system

    .. math:: (I - P_{\pi}[U, U])\, x = P_{\pi}[U, \mathit{target}]\, \mathbf 1.

    ``method="auto"`` solves the chain component by component in topological order
    (exact, single-threaded: an iterative solve slowed 88x on a loaded machine when BLAS
    threads fought); ``"direct"`` factorises the whole system (sparse LU);
    ``"iterative"`` uses BiCGSTAB to a residual of 1e-12.  ``layers``: the components and
    levels of the MDP's support graph (``Quotient.layers``, from the analysis), so that
    ``"auto"`` walks them instead of decomposing the chain again.
    """
    target = as_state_mask(mdp, target, "target")
    policy = np.asarray(policy, dtype=np.int64)
    n = mdp.n_states
    if policy.shape != (n,):
        raise ValueError(f"policy: expected shape ({n},), got {policy.shape}")
    stop = policy < 0
    absorbing = absorbing_states(mdp)
    bad_stop = np.flatnonzero(stop & ~target & ~absorbing)
    if bad_stop.size:
        raise ValueError(
            f"policy: -1 (stop) in non-target, non-absorbing states {bad_stop[:10].tolist()}"
        )
    acting = ~stop & ~target
    lo, hi = mdp.row_groups[:-1], mdp.row_groups[1:]
    bad = np.flatnonzero(acting & ((policy < lo) | (policy >= hi)))
    if bad.size:
        raise ValueError(
            f"policy: choice not owned by its state in states {bad[:10].tolist()}"
        )
    states = np.flatnonzero(acting)
    chain = sp.csr_array(sp.csr_array(mdp.matrix)[policy[states]])  # rows: acting states
    coo = sp.coo_array(chain)
    keep = coo.data > 0
    src, dst = states[coo.row[keep]], np.asarray(coo.col[keep], dtype=np.int64)
    can = backward_reachable(n, src, dst, target)
    solve = acting & can
    values = np.where(target, 1.0, 0.0)
    if not solve.any():
        return values
    rows = np.flatnonzero(solve[states])  # positions in `chain` of the states to solve
    idx = np.flatnonzero(solve)
    sub = chain[rows]
    a = sp.eye_array(idx.size, format="csc") - sp.csc_array(sub[:, idx])
    b = np.asarray(sub @ target.astype(np.float64)).ravel()
    x = _solve_transient(a, b, method, None if layers is None
                         else (np.asarray(layers[0])[idx], layers[1]))
    values[idx] = np.clip(x, 0.0, 1.0)
    return values


def _solve_transient(
    a: sp.csc_array, b: np.ndarray, method: Literal["auto", "direct", "iterative"],
    layers: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Solve ``(I - Q) x = b`` for a transient sub-stochastic ``Q``: by components in
    topological order (``"auto"``, :func:`mitld_lp.solvers.topological.solve_chain`),
    one sparse LU (``"direct"``) or BiCGSTAB to a residual of 1e-12 (``"iterative"``)."""
    if method == "auto":
        return solve_chain(sp.csr_array(sp.eye_array(b.shape[0], format="csr") - a), b,
                           layers)
    if method == "direct":
        return np.asarray(spla.spsolve(a, b), dtype=np.float64).ravel()
    x, info = spla.bicgstab(sp.csr_array(a), b, rtol=1e-14, atol=1e-15, maxiter=5_000)
    x = np.asarray(x, dtype=np.float64).ravel()
    residual = float(np.max(np.abs(a @ x - b), initial=0.0))
    if info != 0 or residual > 1e-12:
        logger.info("BiCGSTAB did not converge (info %d, residual %.1e)", info, residual)
    return x
