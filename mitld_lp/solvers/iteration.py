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
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.mdp import MDP, absorbing_states, as_state_mask
from mitld_lp.solvers.graph import backward_reachable, segmented_argmax
from mitld_lp.solvers.kernels import Prepared, compiled_sweeps, numpy_sweeps, use_compiled
from mitld_lp.solvers.quotient import lift_policy, quotient_for
from mitld_lp.solvers.reduced import Quotient, greedy_choices
from mitld_lp.solvers.result import IterationResult, Status, read_only
from mitld_lp.solvers.topological import (
    Block,
    Factors,
    blocks,
    improve_policy,
    single_scores,
    solve_chain,
    state_graph,
    transient_solve,
)
from mitld_lp.util.progress import Bar
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.util.traversal import breadth_first_order

__all__ = ["interval_iteration", "interval_iterations", "evaluate_policy"]

logger = logging.getLogger(__name__)

_PROGRESS_MIN_STATES = 10_000
"""Below this many reduced states no progress bar is shown (the run is instant)."""

_SWEEPS_BEFORE_POLICY = 100
"""Sweeps of a component before it is jumped by policy evaluation (module docs)."""
_COMPILED_SWEEPS_BEFORE_POLICY = 1000
"""The same for the compiled Gauss--Seidel sweeps: a sweep costs a few microseconds
per thousand transitions there, so a thousand cost about what the jump's factorisations
do on the bus blocks (where 200-800 close the gap).  A block whose gap shrinks too
slowly to close by then is jumped early (:func:`_hopeless`): on QVBS consensus N=6 K=2
the six large blocks (17,280 to 375,240 states) each took their thousand sweeps and
were then jumped anyway (interval iteration 73 s); jumped after 192-208 sweeps, the
same bracket in 27 s."""



@dataclass(slots=True)
class _Budget:
    """Sweeps and seconds left for one call (mutable: shared by every component)."""

    max_iterations: int
    deadline: float
    iterations: int = 0
    stopped: Status | None = field(default=None)

    def take(self, wanted: int) -> int:
        """Up to ``wanted`` sweeps granted at once (counted when :meth:`spent`); 0 (and
        the reason in ``stopped``) once out of budget."""
        if self.iterations >= self.max_iterations:
            self.stopped = Status.MAX_ITERATIONS
            return 0
        if time.perf_counter() >= self.deadline:
            self.stopped = Status.TIME_LIMIT
            return 0
        return min(wanted, self.max_iterations - self.iterations)

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


def _sweeps(block: Block, exits: np.ndarray, bounds: np.ndarray, tol: float,
            budget: _Budget, width: Literal["initial", "max"], initial: int, bar: Bar,
            limit: int | None = None) -> bool:
    """Iterate the block's bounds in place (``bounds[block.states]``: a lower and an
    upper column per model, ``exits`` their exit rewards per choice) until every
    model's gap is below ``tol`` (at ``initial`` or over the block); ``False`` if the
    budget or ``limit`` sweeps ran out first.  One sparse product serves every column."""
    local = bounds[block.states]

    def gap() -> float:
        spread = local[:, 1::2] - local[:, 0::2]
        if width == "initial" and initial >= 0:
            return float(np.max(spread[initial]))
        return float(np.max(spread, initial=0.0))

    done = 0
    try:
        while gap() >= tol:
            if (limit is not None and done >= limit) or not budget.spend():
                return False
            local = np.maximum.reduceat(block.inner @ local + exits, block.starts, axis=0)
            done += 1
            if done % 100 == 0:
                bar.update(100)
        return True
    finally:
        bounds[block.states] = local


_CHUNK = 16
"""Sweeps of a block between two looks at the budget and the clock."""

_FORECAST_FROM = 192
"""Sweeps of a block before its gap's rate of decrease is read: before the policy jump
(``limit``), a block whose gap, shrinking as it did over the last
:data:`_FORECAST_WINDOW` sweeps, would still be open at twice the sweeps left is jumped
at once instead of swept to the limit."""
_FORECAST_WINDOW = 64


def _block_sweeps(block: Block, prep: Prepared, exits: np.ndarray, bounds: np.ndarray,
                  tol: float, budget: _Budget, bar: Bar, compiled: bool,
                  limit: int | None = None) -> bool:
    """Sweep the block's bounds in place (``bounds[block.states]``, a lower and an upper
    column per model; :mod:`mitld_lp.solvers.kernels`: each self-loop solved exactly,
    Gauss--Seidel if ``compiled``, else Jacobi) until every model's gap on the block is
    below ``tol``; ``False`` if the budget or ``limit`` sweeps ran out first."""
    run = compiled_sweeps if compiled else numpy_sweeps
    local = bounds[block.states]
    done = 0
    seen: list[tuple[int, float]] = []  # (sweeps done, gap) after each chunk
    try:
        while True:
            wanted = _CHUNK if limit is None else min(_CHUNK, limit - done)
            granted = budget.take(wanted) if wanted > 0 else 0
            swept, gap = run(prep, exits, local, tol, granted)
            budget.iterations += swept
            done += swept
            bar.update(swept)
            if gap < tol:
                return True
            if granted == 0:
                return False
            if limit is not None:
                seen.append((done, gap))
                if _hopeless(seen, tol, limit):
                    return False
    finally:
        bounds[block.states] = local


def _hopeless(seen: list[tuple[int, float]], tol: float, limit: int) -> bool:
    """Whether a block's gap, read after each chunk of sweeps (``seen``), would still be
    above ``tol`` at twice the sweeps left to ``limit`` if it kept shrinking at the rate
    of the last :data:`_FORECAST_WINDOW` sweeps (never before :data:`_FORECAST_FROM`)."""
    done, gap = seen[-1]
    if done < _FORECAST_FROM:
        return False
    then = next(((d, g) for d, g in reversed(seen) if d <= done - _FORECAST_WINDOW), None)
    if then is None or then[1] <= 0.0:
        return False
    rate = (gap / then[1]) ** (1.0 / (done - then[0]))  # per sweep
    if rate >= 1.0:
        return True
    needed = np.log(tol / gap) / np.log(rate)
    return bool(needed > 2 * (limit - done))


def _jump(block: Block, lo: np.ndarray, hi: np.ndarray, tol: float) -> bool:
    """Try the verified policy jump of the module docs on ``block``; update ``lo`` and
    ``hi`` where it proves better bounds.  ``True`` if both bounds were proven.

    Measured and not done: stopping the policy iterations once no choice gains more
    than ``tol / 64`` over the longest exit time (both bounds are checked whatever the
    policy), redone to the exact fixpoint where the checks then refuse.  On
    ``bus_scaled`` n64 d3 it saves three of the 8,192-state block's fourteen
    factorisations (interval iteration 0.46 -> 0.40 s), nothing on d10; a slippery
    40x40 grid (``experiments/bench_big_component.py``) and one random model in four
    needed the redo, as a choice tied with the policy took far longer to leave than the
    policy's own, which the upper bound's margin must cover."""
    exit2 = block.exits(lo, hi)
    groups = np.append(block.starts, block.choices.shape[0])
    local = np.column_stack([lo[block.states], hi[block.states]])
    start = segmented_argmax(exit2[:, 0] + block.inner @ local[:, 0], groups)
    factors = Factors()  # the three policy iterations below share their factorisations
    chosen, v, t = improve_policy(block, exit2[:, 0], start, factors=factors)
    eps = (tol / 4.0) / float(np.max(t))
    lower = v - eps * t
    inner_ld = block.inner.astype(np.longdouble)
    lower_ok = bool(np.all(exit2[chosen, 0] + (inner_ld @ lower)[chosen] >= lower))
    chosen_hi, w, _ = improve_policy(block, exit2[:, 1], chosen, factors=factors)
    # The shift must cover the slowest of the (nearly) optimal choices, not only the
    # policy's: t_hi = 1 + max over choices within tol/4 of optimal of P t_hi.
    owner_w = np.repeat(w, np.diff(groups))
    tied = (owner_w - (exit2[:, 1] + inner_ld @ w)) < tol / 4.0
    _, t_hi, _ = improve_policy(block, np.ones(block.choices.shape[0]), chosen_hi, tied,
                                factors=factors)
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


def _single_states(q: Quotient, states: np.ndarray, rewards: np.ndarray,
                   bounds: np.ndarray) -> None:
    r"""The single-state components ``states`` solved exactly from the bounds
    downstream, every column at once: ``v(s) = max_c r(c) / (1 - p(c))`` scored by
    :func:`mitld_lp.solvers.topological.single_scores` as the LP's single states are
    (``rewards``: the one-step probability of the target per choice and column)."""
    if states.size == 0:
        return
    _, score, groups = single_scores(q, q.order, states, rewards, bounds)
    bounds[states] = np.maximum.reduceat(score, groups[:-1], axis=0)


def _topological(q: Quotient, rewards: np.ndarray, bounds: np.ndarray, tol: float,
                 budget: _Budget, bar: Bar, *, from_initial: bool,
                 compiled: bool | None) -> None:
    """Fill ``bounds`` (a lower and an upper column per model, ``rewards`` their
    one-step target probabilities) level by level (module docs); stops early out of
    budget.  ``from_initial``: only the states the initial state can reach (their
    successors are reachable too, so nothing they need is skipped); the others keep
    ``[0, 1]``.  ``compiled``: the blocks are swept by the compiled kernel (``None``:
    the blocks :func:`~mitld_lp.solvers.kernels.use_compiled` picks, numba loaded at the
    first of them)."""
    blk = blocks(q)
    skip = None
    if from_initial:
        order = breadth_first_order(state_graph(q), q.initial)
        skip = np.ones(q.n_states, dtype=bool)
        skip[np.asarray(order)] = False
    for level in blk.walk(skip=skip):
        _single_states(q, level.single, rewards, bounds)
        rest = level.rest
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        exits = rewards[block.choices] + block.outer @ bounds
        prep = Prepared(block.inner, block.groups)
        fast = (use_compiled(q.matrix.nnz, block.inner.nnz) if compiled is None
                else compiled)
        if _block_sweeps(block, prep, exits, bounds, tol, budget, bar, fast,
                         _COMPILED_SWEEPS_BEFORE_POLICY if fast else _SWEEPS_BEFORE_POLICY):
            continue
        if budget.stopped is None:
            proven = True
            for j in range(bounds.shape[1] // 2):
                model = replace(block, to_target=rewards[block.choices, 2 * j])
                lo, hi = bounds[:, 2 * j], bounds[:, 2 * j + 1]  # views: written through
                proven &= _jump(model, lo, hi, tol)
            spread = bounds[rest][:, 1::2] - bounds[rest][:, 0::2]
            if proven and float(np.max(spread)) < tol:
                continue
        if not _block_sweeps(block, prep, exits, bounds, tol, budget, bar, fast):
            return


def interval_iteration(
    mdp: MDP,
    target: np.ndarray,
    *,
    quotient: Quotient | None = None,
    tol: float = defaults.TOL,
    max_iterations: int = 1_000_000,
    progress: bool | None = None,
    gap: Literal["initial", "max"] = "initial",
    topological: bool = True,
    time_limit: float | None = None,
    compiled: bool | None = None,
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
    ``compiled``: the blocks swept by the compiled (numba) Gauss--Seidel kernel
    (:mod:`mitld_lp.solvers.kernels`); None (default) uses it, when numba is installed,
    on the blocks of at least ``kernels.COMPILED_MIN_BLOCK_ENTRIES`` entries of a
    quotient of at least ``kernels.COMPILED_MIN_ENTRIES``; ``True`` on every block,
    ``False`` never.
    """
    q = quotient_for(mdp, target, quotient)
    (result,) = interval_iterations(mdp, [q], tol=tol, max_iterations=max_iterations,
                                    progress=progress, gap=gap, topological=topological,
                                    time_limit=time_limit, compiled=compiled)
    return result


def interval_iterations(
    mdp: MDP,
    quotients: Sequence[Quotient],
    *,
    tol: float = defaults.TOL,
    max_iterations: int = 1_000_000,
    progress: bool | None = None,
    gap: Literal["initial", "max"] = "initial",
    topological: bool = True,
    time_limit: float | None = None,
    compiled: bool | None = None,
) -> list[IterationResult]:
    """:func:`interval_iteration` of several models in one pass: ``quotients`` share
    their matrix and block order (both truncation models of a product, from
    :func:`mitld_lp.solvers.analysis.analyse`) and differ in their one-step target
    probabilities; each sweep updates the lower and upper bounds of every model with one
    sparse product.  One result per quotient; the sweep count and the seconds are the
    pass's."""
    start = time.perf_counter()
    q = quotients[0]
    if any(other.matrix is not q.matrix or other.order is not q.order
           for other in quotients[1:]):
        raise ValueError("quotients: iterated together only when they share their matrix "
                         "and block order (one analysis)")
    n, k = q.n_states, len(quotients)
    rewards = np.repeat(np.column_stack([o.to_target for o in quotients]), 2, axis=1)
    bounds = np.zeros((n, 2 * k))
    for j, o in enumerate(quotients):
        bounds[:, 2 * j + 1] = np.where(o.zero, 0.0, 1.0)
    budget = _Budget(max_iterations,
                     start + time_limit if time_limit is not None else np.inf)
    bar = progress_bar(progress if n >= _PROGRESS_MIN_STATES else False, total=None,
                       desc="interval iteration", unit="it", leave=False)
    decided = gap == "initial" and q.initial < 0
    try:
        if n and not decided:
            if topological:
                _topological(q, rewards, bounds, tol, budget, bar,
                             from_initial=gap == "initial", compiled=compiled)
            else:
                whole = Block.of(q, np.arange(n))
                _sweeps(whole, rewards[whole.choices] + whole.outer @ bounds, bounds, tol,
                        budget, gap, q.initial, bar)
    finally:
        bar.close()
    np.clip(bounds, 0.0, 1.0, out=bounds)  # rounding can push the upper bound past 1
    seconds = time.perf_counter() - start
    return [_result(mdp, o, bounds[:, 2 * j:2 * j + 2], tol, gap, decided, budget, seconds,
                    time_limit) for j, o in enumerate(quotients)]


def _result(mdp: MDP, q: Quotient, bounds: np.ndarray, tol: float,
            gap: Literal["initial", "max"], decided: bool, budget: _Budget, seconds: float,
            time_limit: float | None) -> IterationResult:
    """One model's bounds of the pass as its :class:`IterationResult`."""
    n = q.n_states
    width = 0.0 if n == 0 or decided else (
        float(bounds[q.initial, 1] - bounds[q.initial, 0]) if gap == "initial"
        else float(np.max(bounds[:, 1] - bounds[:, 0])))
    status = budget.stopped or (Status.OPTIMAL if width < tol else Status.MAX_ITERATIONS)
    lower = q.lift(bounds[:, 0])
    upper = q.lift(bounds[:, 1])
    policy = lift_policy(mdp, q, greedy_choices(q, bounds[:, 0]) if n else np.zeros(0, int))
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
    chain = sp.csr_array(mdp.matrix)[policy[states]]  # rows: acting states
    counts = np.diff(chain.indptr)
    positive = chain.data > 0
    can = backward_reachable(n, np.repeat(states.astype(chain.indices.dtype), counts)[positive],
                             chain.indices[positive], target)
    del positive
    solve = acting & can
    values = np.where(target, 1.0, 0.0)
    if not solve.any():
        return values
    idx = np.flatnonzero(solve)
    rows = np.flatnonzero(solve[states])  # positions in `chain` of the states to solve
    b = (chain @ target.astype(np.float64))[rows]
    sub = _restricted(chain, rows, solve[states], idx, n)
    del chain  # the policy's rows are not needed while the system is solved
    x = _solve_transient(sub, b, method,
                         None if layers is None else (np.asarray(layers[0])[idx], layers[1]))
    values[idx] = np.clip(x, 0.0, 1.0)
    return values


def _restricted(chain: sp.csr_array, rows: np.ndarray, row_kept: np.ndarray,
                idx: np.ndarray, n: int) -> sp.csr_array:
    """``chain[rows][:, idx]`` as a square CSR matrix, made in one pass over ``chain``'s
    entries (SciPy's row and column indexing would copy the chain twice more)."""
    pos = np.full(n, -1, dtype=np.int64)
    pos[idx] = np.arange(idx.size)
    col = pos[chain.indices]
    del pos
    keep = (col >= 0) & np.repeat(row_kept, np.diff(chain.indptr))
    ends = np.concatenate([[0], np.cumsum(keep)])
    per_row = (ends[chain.indptr[1:]] - ends[chain.indptr[:-1]])[rows]
    indptr = np.concatenate([[0], np.cumsum(per_row)])
    return sp.csr_array((chain.data[keep], col[keep], indptr), shape=(idx.size, idx.size))


def _solve_transient(
    chain: sp.csr_array, b: np.ndarray, method: Literal["auto", "direct", "iterative"],
    layers: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Solve ``x = b + Q x`` for a transient sub-stochastic ``Q`` (``chain``): by
    components in topological order (``"auto"``,
    :func:`mitld_lp.solvers.topological.solve_chain`), one sparse LU of ``I - Q``
    (``"direct"``, :func:`mitld_lp.solvers.topological.transient_solve`) or BiCGSTAB
    to a residual of 1e-12 (``"iterative"``)."""
    if method == "auto":
        return solve_chain(chain, b, layers)
    if method == "direct":
        return transient_solve(chain, b)
    import scipy.sparse.linalg as spla

    a = sp.csc_array(sp.eye_array(b.shape[0], format="csc") - chain)
    x, info = spla.bicgstab(sp.csr_array(a), b, rtol=1e-14, atol=1e-15, maxiter=5_000)
    x = np.asarray(x, dtype=np.float64).ravel()
    residual = float(np.max(np.abs(a @ x - b), initial=0.0))
    if info != 0 or residual > 1e-12:
        logger.info("BiCGSTAB did not converge (info %d, residual %.1e)", info, residual)
    return x
