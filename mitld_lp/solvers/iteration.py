r"""Interval iteration for maximal (or minimal) reachability (the exact evaluation of a
policy, :func:`evaluate_policy`, lives in :mod:`mitld_lp.solvers.evaluation`).

Interval iteration (Haddad & Monmege, TCS 2018; Baier et al., CAV 2017) runs the
Bellman operator

.. math::

    (T x)(s) = \max_{c \in \mathit{Act}(s)} \hat P(c, \mathit{target})
               + \sum_{s'} \hat P(c, s')\, x(s')

(:math:`\min_c` for a minimum: the quotient's ``sense``) on the quotient
(:func:`mitld_lp.solvers.quotient.reduce`: no end component is left) from two starting
points: ``x = 0`` (increases to the optimum from below) and ``x = 1`` on the maybe
states (decreases to it from above; this needs the quotient: on an MDP with end
components the upper sequence can get stuck above the optimum).  Both vectors are
updated together with one sparse product and a segmented maximum (minimum).

**Stopping.**  A bracket is closed when its gap is below the absolute ``tol`` and, with
a relative ``precision`` (default :data:`mitld_lp.defaults.PRECISION`, 1e-6), below
``precision`` times its lower bound: an optimum of 1e-30 is bracketed to six digits,
not to 1e-9.  The iteration first closes every gap to ``tol`` alone, as it always did;
only where the bracket it stops at is then wider than the relative precision are the
components walked again with both thresholds per state (a state's relative gap bounds
its predecessors': each weighs its successors' gaps by probabilities summing to at
most 1), so an answer of ordinary size costs nothing more.

**Topological order** (``topological=True``, the default; this is how Storm's sound
check works): the quotient's strongly connected components are solved level by level,
downstream first (:mod:`mitld_lp.solvers.topological`).  A single-state component is
solved exactly from the bounds downstream (lower from lower, upper from upper); the
non-trivial components of a level are iterated on their own until their gap is below
``tol``, with the bounds downstream as constants.

A component that drains slowly (an event of hazard 1e-6 leaves it once in a million
steps) would need millions of sweeps.  After ``_SWEEPS_BEFORE_POLICY`` sweeps such a
component is *jumped* (:mod:`mitld_lp.solvers.policy_jump`): a policy is improved to a
fixpoint with exact solves of its chain (policy iteration, each improvement looking
ahead by a few Bellman sweeps), and the candidate bounds it gives are kept only if they
prove themselves.  With
``W = u + P W`` the policy's expected total of a positive ``u`` before it leaves the
component (``u = 1``: its expected number of steps ``t``) and ``e > 0``, ``L = v - e W``
satisfies ``L <= T(L)`` (``T_pi(L) = L + e u``) and ``U = w + e W'`` (``w`` from the
upper exits, ``W'`` the largest over the nearly optimal choices) is kept if
``T(U) <= U``.  On a quotient (no end components) ``x <= T(x)`` implies ``x <= Pmax``
and ``T(x) <= x`` implies ``x >= Pmax``, so the checks (done in extended precision,
then rounded outwards) make the jump as sound as a sweep.  ``u`` is each state's gap
threshold, so ``e W`` is a quarter of it: ``tol`` alone gives ``u = 1``, ``W = t``; with
the relative precision ``u`` follows the values, and a component of values near 1e-30
gets bounds within ``precision`` of them.  For a minimum the roles swap: the policy's
own values bound the optimum from above (checked on the policy's choices), the lower
bound is checked over every choice.

A block is jumped before ``_SWEEPS_BEFORE_POLICY`` sweeps where the rate at which its
gap shrinks forecasts that the sweeps cannot close it by then (``_hopeless``).  A
compiled block is first looked at after 32 sweeps (``_EARLY``): one forecast to need
many more is jumped there if the jump's cost, estimated from the block's structure
(:mod:`mitld_lp.solvers.jump_cost`: entries touched, no clock), is at most half what
the sweeps it would save cost; a jump whose rounds of policy iteration (their LUs) are
forecast to pass what they cost is abandoned, its bounds untouched, and the block swept on.  The
compiled sweeps visit a block's states by their distance to the target inside it
(:mod:`mitld_lp.solvers.sweep_order`), so that one sweep carries the target's value back
across the block.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.mdp import MDP
from mitld_lp.solvers.early_jump import early_jump as _early_jump
from mitld_lp.solvers.evaluation import evaluate_policy
from mitld_lp.solvers.graph import Blocks, Sense
from mitld_lp.solvers.kernels import (
    Prepared,
    compiled_sweeps,
    excess,
    numpy_sweeps,
    put_rows,
    take_rows,
)
from mitld_lp.solvers.level_first import FirstBounds
from mitld_lp.solvers.policy_jump import jump
from mitld_lp.solvers.quotient import lift_policy, quotient_for
from mitld_lp.solvers.reduced import Quotient, greedy_choices
from mitld_lp.solvers.result import IterationResult, Lifted, Status, entry, held
from mitld_lp.solvers.shared_levels import RUNS_MIN_LEVELS, shared_levels, walk_handing
from mitld_lp.solvers.sweep_forecast import close_out
from mitld_lp.solvers.sweep_forecast import needed as _needed
from mitld_lp.solvers.sweep_gate import use_compiled
from mitld_lp.solvers.sweep_order import for_sweeps, value_order, whole
from mitld_lp.solvers.topological import (
    Block,
    SingleLevels,
    blocks,
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
    stopped: Status | None = None

    def take(self, wanted: int) -> int:
        """Up to ``wanted`` sweeps granted at once; 0 (why: ``stopped``) out of budget."""
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
            precision: float | None, sense: Sense, budget: _Budget,
            width: Literal["initial", "max"], initial: int, bar: Bar,
            limit: int | None = None) -> bool:
    """Iterate the block's bounds in place (``bounds[block.states]``: a lower and an
    upper column per model, ``exits`` their exit rewards per choice) until every
    model's gap is below its threshold (``tol``, and ``precision`` times the lower
    bound; at ``initial`` or over the block); ``False`` if the budget or ``limit``
    sweeps ran out first.  One sparse product serves every column."""
    local = take_rows(bounds, block.states)

    def over() -> float:
        if width == "initial" and initial >= 0:
            return excess(local[initial:initial + 1], tol, precision)
        return excess(local, tol, precision)

    done = 0
    try:
        while over() >= 1.0:
            if (limit is not None and done >= limit) or not budget.spend():
                return False
            local = sense.reduce(block.inner @ local + exits, block.starts)
            done += 1
            if done % 100 == 0:
                bar.update(100)
        return True
    finally:
        put_rows(bounds, block.states, local)


_CHUNK = 16
"""Sweeps of a block between two looks at the budget and the clock."""

_FORECAST_FROM = 192
"""Sweeps of a block before its gap's rate of decrease is read: before the policy jump
(``limit``), a block whose gap, shrinking as it did over the last
:data:`_FORECAST_WINDOW` sweeps, would still be open at twice the sweeps left is jumped
at once instead of swept to the limit.  Measured and not done: "open at the limit"
instead of "at twice the sweeps left".  On QVBS ``consensus`` 6-2 the large
blocks' gaps shrink by a steady 0.983 a sweep, so at 192 sweeps they are forecast to
close within twice the 808 left, and are swept to 784-800 and jumped there (the block
of 89,760 states: 2.6 s CPU of sweeps, a jump of 0.65 s); jumped at 192, its sweeps
took 1.1 s and its jump 8.1 s, as policy iteration from the greedy policy of a lower
bound still 0.05 off takes many more rounds, each a factorisation."""
_FORECAST_WINDOW = 64
_EARLY = (32, 16, 256)
"""The compiled sweeps' early look (:func:`_needed` read from 32 sweeps over the last
16): a block forecast to need more than 256 sweeps more is jumped there, from the
policy greedy on the bounds its sweeps started from, if the jump's cost is at most half
the sweeps' it would save (those forecast still needed, at most the limit's left), both
estimated from the block's structure in entries touched
(:mod:`mitld_lp.solvers.jump_cost`; before the work, no clock read: the same block
decides the same on an idle and on a loaded machine).  The jump abandons
(:class:`~mitld_lp.solvers.policy_jump.Abandoned`) before a round of policy iteration
that its forecast (the switches' rate) takes past the rounds those sweeps pay for, and
the block is swept on as before.  QVBS ``consensus`` 6-2 ``c2``'s three large blocks
(87,225, 139,566 and 93,067 states) cost 1.4-1.5, 3.6 and 2.6 s jumped at once against
2.9, 5.8 and 4.2 s of sweeps; ``bus_scaled`` n128 d3's blocks of 32,768 and 16,384
states (grids of depth 254: their LUs fill, policy iteration takes many rounds) took a
13.6 s jump where 1,000 sweeps and a late jump close them.  The last wave's budget in
CPU seconds (measured as the sweeps ran) started the bus jumps and abandoned each after
two rounds (5.90 -> 6.65 s); the cost model refuses them before the work
(``experiments/results/bench_sweeps_jump_cost.md``)."""
_NUMPY_FORECAST_FROM = 8
"""The same for the NumPy (Jacobi) sweeps, whose limit is :data:`_SWEEPS_BEFORE_POLICY`
(their forecast from :data:`_FORECAST_FROM` was never read), over the last
:data:`_NUMPY_FORECAST_WINDOW`.  QVBS ``consensus`` 4-4: each of the four blocks (3,904
to 16,336 states) kept its gap at ``tol``'s 1e9 over the threshold for 32 sweeps and
above 0.99e9 after 100 (an upper bound of 1 moves by a random walk's escape), and was
jumped anyway; jumped at 32 the same blocks close (400 -> 128 sweeps).  What that
saves, the policy jump's extra rounds from a rougher start take back in part: solve
stage 1.07-1.28 -> 0.91-1.06 s CPU on ``c2``, 1.57-1.87 -> 1.62-1.74 s on
``disagree`` (three runs each, twice, in one session); on ``bus_scaled`` n64 d3
(blocks of NumPy size) 200 -> 64 sweeps, 1.93 -> 1.96 s.  Read from 8 sweeps over 4
since the jump's look-ahead (:data:`_NUMPY_CHUNK`)."""
_NUMPY_FORECAST_WINDOW = 4
_NUMPY_CHUNK = 4
"""The NumPy sweeps' chunk (:data:`_CHUNK`), so that their forecast can be read early.
With the policy jump's look-ahead (:mod:`mitld_lp.solvers.policy_jump`) a rougher start
costs the jump little: QVBS ``consensus`` 4-4 ``c2``'s four blocks each kept their gap
flat for the first sweeps and are jumped at 8 (forecast from 8 over 4) instead of 32
(from 32 over 16): 128 -> 32 sweeps, solve stage 0.78-0.80 -> 0.67-0.70 s CPU in
pairs of runs in one session, the same jumps' cost (0.24 against 0.24 s on its two
large blocks)."""


@dataclass(slots=True)
class _Early:
    """What a block's sweeps read when the early look (:data:`_EARLY`) stopped them."""

    done: int = 0
    needed: float = 0.0
    stopped: bool = False


def _block_sweeps(block: Block, prep: Prepared, exits: np.ndarray, bounds: np.ndarray,
                  tol: float, precision: float | None, sense: Sense, budget: _Budget,
                  bar: Bar, compiled: bool, limit: int | None = None,
                  early: _Early | None = None) -> bool:
    """Sweep the block's bounds in place (``bounds[block.states]``, a lower and an upper
    column per model; :mod:`mitld_lp.solvers.kernels`: each self-loop solved exactly,
    Gauss--Seidel if ``compiled``, else Jacobi) until every model's gap on the block is
    below its threshold; ``False`` if the budget or ``limit`` sweeps ran out first.
    ``early`` (with ``limit``): the look of :data:`_EARLY` is taken, and what it read
    written there if it stops the sweeps."""
    run = compiled_sweeps if compiled else numpy_sweeps
    forecast = ((_FORECAST_FROM, _FORECAST_WINDOW) if compiled
                else (_NUMPY_FORECAST_FROM, _NUMPY_FORECAST_WINDOW))
    local = take_rows(bounds, block.states)
    done = 0
    seen: list[tuple[int, float]] = []  # (sweeps done, gap over threshold) per chunk
    try:
        while True:
            chunk = _CHUNK if compiled else _NUMPY_CHUNK
            wanted = chunk if limit is None else min(chunk, limit - done)
            granted = budget.take(wanted) if wanted > 0 else 0
            swept, over = run(prep, exits, local, tol, granted, sense, precision)
            budget.iterations += swept
            done += swept
            bar.update(swept)
            if over < 1.0:
                return True
            if granted == 0:
                return False
            if limit is not None:
                seen.append((done, over))
                if compiled:
                    close_out(prep, seen, _CHUNK)
                if early is not None and done < forecast[0]:
                    needed = _needed(seen, *_EARLY[:2])
                    if needed is not None and needed > min(_EARLY[2], 2 * (limit - done)):
                        early.done, early.needed, early.stopped = done, needed, True
                        return False
                elif _hopeless(seen, limit, *forecast):
                    return False
    finally:
        put_rows(bounds, block.states, local)


def _hopeless(seen: list[tuple[int, float]], limit: int, start: int = _FORECAST_FROM,
              window: int = _FORECAST_WINDOW) -> bool:
    """Whether a block's gap (over its threshold, read after each chunk of sweeps:
    ``seen``) would still be open at twice the sweeps left to ``limit`` if it kept
    shrinking at the rate of the last ``window`` sweeps (never before ``start``)."""
    needed = _needed(seen, start, window)
    return needed is not None and needed > 2 * (limit - seen[-1][0])


def _saved(early: _Early, limit: int) -> float:
    """The sweeps the early jump would save (:data:`_EARLY`): those forecast still
    needed, at most the ``limit``'s left."""
    return min(early.needed, float(limit - early.done))


def _topological(q: Quotient, rewards: np.ndarray, bounds: np.ndarray, tol: float,
                 precision: float | None, budget: _Budget, bar: Bar, *,
                 skip: np.ndarray | None, compiled: bool | None,
                 models: list[Quotient] | None = None) -> None:
    """Fill ``bounds`` (a lower and an upper column per model, ``rewards`` their
    one-step target probabilities) level by level (module docs) until every gap is
    below its threshold (``tol``, and ``precision`` times the lower bound); stops early
    out of budget.  ``skip``: states left out (those the initial state cannot reach:
    their successors are unreachable too, so nothing the others need is skipped); they
    keep what they had.  ``compiled``: the blocks are swept by the compiled kernel
    (``None``: the blocks :func:`~mitld_lp.solvers.sweep_gate.use_compiled` picks, numba
    loaded at the first of them).  ``models``: the quotients iterated (one
    matrix), for whose LPs a quotient of single states only hands over its walk
    (:func:`~mitld_lp.solvers.shared_levels.walk_handing`)."""
    blk = blocks(q)
    if blk.n_levels < RUNS_MIN_LEVELS:  # the LP walks its levels one by one
        _levels(q, blk, rewards, bounds, tol, precision, budget, bar, SingleLevels(
            q, blk, skip), skip=skip, compiled=compiled)
        return
    # the LP's levels (shared_levels: built once a quotient), the skipped single states
    # walked too and their bounds put back: no state the initial one reaches reads them
    singles = shared_levels(q, blk)
    held = None if skip is None else singles.states[skip[singles.states]]
    kept = None if held is None else take_rows(bounds, held)
    try:
        _levels(q, blk, rewards, bounds, tol, precision, budget, bar, singles, skip=skip,
                compiled=compiled, models=models)
    finally:
        if held is not None:
            put_rows(bounds, held, kept)


def _levels(q: Quotient, blk: Blocks, rewards: np.ndarray, bounds: np.ndarray, tol: float,
            precision: float | None, budget: _Budget, bar: Bar, singles: SingleLevels, *,
            skip: np.ndarray | None, compiled: bool | None,
            models: list[Quotient] | None = None) -> None:
    """:func:`_topological`'s walk of the levels with the single states' ``singles``
    (with no block and ``models``, the walk that hands the LPs their values)."""
    sense = q.sense
    done = 0  # the levels whose single states are solved
    with_blocks = np.zeros(blk.n_levels, dtype=bool)  # not np.unique: it imports numpy.ma
    with_blocks[blk.level[blk.size > 1]] = True
    for index in np.flatnonzero(with_blocks).tolist():  # the levels with blocks
        singles.solve(done, index + 1, rewards, bounds)
        done = index + 1
        rest = blk.states_at(index)
        rest = rest[blk.size[blk.component[rest]] > 1]
        if skip is not None:
            rest = rest[~skip[rest]]
        if rest.size == 0:
            continue
        block = Block.of(q, rest)
        fast = (use_compiled(q.matrix.nnz, block.inner.nnz, block, bounds.shape[1])
                if compiled is None else compiled)
        if fast:  # the order before the exits: its searches peak without them beside
            order = value_order(block)[::-1]
        exits = take_rows(rewards, block.choices) + block.outer @ bounds
        if fast:  # the target's value carried back in one sweep, the block renumbered
            # for the kernel's sweep from last to first (sweep_order's docs)
            held = [block]
            del block  # renumbered lets the old block's matrices go as it goes
            block, exits = for_sweeps(held, order, exits)  # Block.of's, without its outer
            del order
            rest = block.states
        groups = block.groups  # the block's starts a view of them: held once, not twice
        block = replace(block, starts=groups[:-1])
        prep = Prepared(block.inner, groups)
        del groups
        limit = _COMPILED_SWEEPS_BEFORE_POLICY if fast else _SWEEPS_BEFORE_POLICY
        # a copy: the early jump (compiled blocks only) starts greedy on it
        first = FirstBounds(bounds, block.states) if fast else None
        early = _Early() if fast else None
        if _block_sweeps(block, prep, exits, bounds, tol, precision, sense, budget, bar,
                         fast, limit, early):
            continue
        if early is not None and early.stopped and budget.stopped is None:
            # the jump's cost forecast on the block as swept; the moves out of it
            # (``whole``) made only for a jump that is taken
            jumped = _early_jump(block, rewards, bounds, first.values(), tol, precision,
                                 sense, _saved(early, limit), exits, q)
            if jumped is True:
                continue
            block = jumped or block
            if _block_sweeps(block, prep, exits, bounds, tol, precision, sense, budget,
                             bar, fast, limit - early.done):
                continue
        if budget.stopped is None:
            block = whole(q, block)  # the jump's moves out of the block
            proven = True
            for j in range(bounds.shape[1] // 2):
                model = replace(block, to_target=rewards[block.choices, 2 * j])
                lo, hi = bounds[:, 2 * j], bounds[:, 2 * j + 1]  # views: written through
                proven &= jump(model, lo, hi, tol, precision, sense)
            if proven and excess(bounds[rest], tol, precision) < 1.0:
                continue
        if not _block_sweeps(block, prep, exits, bounds, tol, precision, sense, budget,
                             bar, fast):
            return
    if not (done == 0 and models is not None
            and walk_handing(q, singles, rewards, bounds, models)):
        singles.solve(done, blk.n_levels, rewards, bounds)


def interval_iteration(
    mdp: MDP,
    target: np.ndarray,
    *,
    quotient: Quotient | None = None,
    sense: Sense = Sense.MAX,
    tol: float = defaults.TOL,
    precision: float | None = defaults.PRECISION,
    max_iterations: int = 1_000_000,
    progress: bool | None = None,
    gap: Literal["initial", "max"] = "initial",
    topological: bool = True,
    time_limit: float | None = None,
    compiled: bool | None = None,
) -> IterationResult:
    """Sound bounds ``lower <= Pmax(F target) <= upper`` on every state (``Pmin`` with
    ``sense=Sense.MIN``).

    ``topological=False`` sweeps the whole quotient at once and stops when the gap
    ``upper - lower`` is below its threshold at the initial state (``gap="initial"``,
    the default) or at every state (``gap="max"``): below ``tol``, and below
    ``precision`` times the lower bound (relative; ``None``: ``tol`` alone).
    ``topological=True`` (module docs) brings every component below its thresholds in
    turn: with ``gap="initial"`` every one the initial state can reach, with
    ``gap="max"`` all of them.  Either way the bounds are valid everywhere, and if the
    initial state is decided by the graph analysis (target or prob-0) no iteration is
    needed with ``gap="initial"``.  ``max_iterations`` counts sweeps (over all
    components); reaching it gives status ``MAX_ITERATIONS``, reaching ``time_limit``
    seconds ``TIME_LIMIT``, both with the bracket so far (``[0, 1]`` where nothing was
    done). ``quotient``: ``reduce(mdp, target, sense=sense)`` if the caller already has
    it (the result then holds it until its policy is read: :class:`IterationResult`).
    ``compiled``: the blocks swept by the compiled (numba) Gauss--Seidel kernel
    (:mod:`mitld_lp.solvers.kernels`); None (default) uses it, when numba is installed,
    on the blocks of at least ``kernels.COMPILED_MIN_BLOCK_ENTRIES`` entries of a
    quotient of at least ``kernels.COMPILED_MIN_ENTRIES``, and on the smaller blocks
    there that :mod:`mitld_lp.solvers.sweep_gate` forecasts cheaper so (deep blocks,
    which NumPy's sweeps would leave to the policy jump); ``True`` on every block,
    ``False`` never."""
    q = quotient_for(mdp, target, quotient, sense)
    (result,) = interval_iterations(mdp, [q], tol=tol, precision=precision,
                                    max_iterations=max_iterations, progress=progress,
                                    gap=gap, topological=topological,
                                    time_limit=time_limit, compiled=compiled)
    if quotient is None:
        result.policy  # noqa: B018 - made while the quotient made here lives
    return result


def interval_iterations(
    mdp: MDP,
    quotients: Sequence[Quotient],
    *,
    tol: float = defaults.TOL,
    precision: float | None = defaults.PRECISION,
    max_iterations: int = 1_000_000,
    progress: bool | None = None,
    gap: Literal["initial", "max"] = "initial",
    topological: bool = True,
    time_limit: float | None = None,
    compiled: bool | None = None,
) -> list[IterationResult]:
    """:func:`interval_iteration` of several models in one pass: ``quotients`` share
    their matrix, block order and sense (both truncation models of a product, from
    :func:`mitld_lp.solvers.analysis.analyse`) and differ in their one-step target
    probabilities; each sweep updates the lower and upper bounds of every model with one
    sparse product.  One result per quotient; the sweep count and the seconds are the
    pass's; each holds its quotient until its policy is read (:class:`IterationResult`)."""
    start = time.perf_counter()
    q = quotients[0]
    if any(other.matrix is not q.matrix or other.order is not q.order
           or other.sense is not q.sense for other in quotients[1:]):
        raise ValueError("quotients: iterated together only when they share their matrix, "
                         "block order and sense (one analysis)")
    if precision is not None and not (0.0 < precision < 1.0):
        raise ValueError(f"precision: a relative precision in (0, 1), got {precision!r}")
    n, k = q.n_states, len(quotients)
    decided = gap == "initial" and q.initial < 0
    if topological and n and not decided and q.order.n_levels >= RUNS_MIN_LEVELS:
        shared_levels(q, q.order)  # _topological's levels, built before the arrays below
    rewards = np.repeat(np.column_stack([o.to_target for o in quotients]), 2, axis=1)
    bounds = np.zeros((n, 2 * k))
    for j, o in enumerate(quotients):
        bounds[:, 2 * j + 1] = np.where(o.zero, 0.0, 1.0)
    budget = _Budget(max_iterations, start + time_limit if time_limit is not None else np.inf)
    bar = progress_bar(progress if n >= _PROGRESS_MIN_STATES else False, total=None,
                       desc="interval iteration", unit="it", leave=False)
    try:
        if n and not decided:
            if topological:
                skip = None
                if gap == "initial":
                    skip = np.ones(q.n_states, dtype=bool)
                    skip[np.asarray(breadth_first_order(_moves(q), q.initial))] = False
                # first to ``tol`` alone (what an answer of ordinary size needs), then,
                # where the bracket is still wider than the relative precision, again
                # with both thresholds per state (module docs)
                _topological(q, rewards, bounds, tol, None, budget, bar, skip=skip,
                             compiled=compiled, models=list(quotients))
                if (precision is not None and budget.stopped is None
                        and _over(bounds, q, gap, tol, precision) >= 1.0):
                    _topological(q, rewards, bounds, tol, precision, budget, bar,
                                 skip=skip, compiled=compiled)
            else:
                whole = Block.of(q, np.arange(n))
                _sweeps(whole, take_rows(rewards, whole.choices) + whole.outer @ bounds,
                        bounds, tol, precision, q.sense, budget, gap, q.initial, bar)
    finally:
        bar.close()
    del rewards  # read by the sweeps alone: gone before the records' columns are copied
    np.clip(bounds, 0.0, 1.0, out=bounds)  # rounding can push the upper bound past 1
    seconds = time.perf_counter() - start
    return [_result(mdp, o, bounds[:, 2 * j:2 * j + 2], tol, precision, gap, decided,
                    budget, seconds, time_limit) for j, o in enumerate(quotients)]


def _moves(q: Quotient) -> sp.csr_array:
    """The quotient's moves between states for the search of the states the initial
    one reaches: each state's row the column indices of its choices' rows (a slice of
    the matrix's own arrays, its probabilities as the weights, no copy), a successor
    reached by several choices listed once a choice.  A search reaches the same states
    as on :func:`~mitld_lp.solvers.topological.state_graph`, whose duplicates merged
    (a sort of every entry) only the strongly connected components need."""
    m = q.matrix
    n = q.row_groups.shape[0] - 1
    index = np.int32 if max(n, m.nnz) < 2**31 else np.int64
    return sp.csr_array((m.data, m.indices.astype(index, copy=False),
                         np.asarray(m.indptr[q.row_groups], dtype=index)), shape=(n, n))


def _over(bounds: np.ndarray, q: Quotient, gap: Literal["initial", "max"], tol: float,
          precision: float | None) -> float:
    """The largest gap over its threshold where the stopping rule looks (the initial
    state, or every state)."""
    if gap == "initial":
        return excess(bounds[q.initial:q.initial + 1], tol, precision) if q.initial >= 0 else 0.0
    return excess(bounds, tol, precision)


def _result(mdp: MDP, q: Quotient, bounds: np.ndarray, tol: float,
            precision: float | None, gap: Literal["initial", "max"], decided: bool,
            budget: _Budget, seconds: float, time_limit: float | None) -> IterationResult:
    """One model's bounds of the pass as its :class:`IterationResult`; the states whose
    value the graph decides as 1 (``q.qualitative.one``) get the bracket ``[1, 1]``."""
    n = q.n_states
    width = 0.0 if n == 0 or decided else (
        float(bounds[q.initial, 1] - bounds[q.initial, 0]) if gap == "initial"
        else float(np.max(bounds[:, 1] - bounds[:, 0])))
    over = 0.0 if n == 0 or decided else _over(bounds, q, gap, tol, precision)
    status = budget.stopped or (Status.OPTIMAL if over < 1.0 else Status.MAX_ITERATIONS)
    # held on the quotient, lifted where read (Lifted), the ones the graph decides set
    # to 1 at the lift where the quotient keeps any (looked up once a model); each
    # column copied: contiguous, as the kernels that read it are compiled for (a
    # strided view is another numba type: a compile mid-solve)
    one = np.asarray(q.qualitative.one, dtype=bool)
    kept = n > 0 and bool(np.any(one & (q.state_map >= 0)))
    lower = held(bounds[:, 0], q.state_map, one, forced=True, kept=kept)
    upper = held(bounds[:, 1], q.state_map, one, forced=True, kept=kept)
    # greedy on a maximum's lower, a minimum's upper bound, at its first read: the
    # copy the record holds (else one of its own)
    side = 0 if q.sense is Sense.MAX else 1
    known = (lower, upper)[side]
    known = known.reduced if isinstance(known, Lifted) else bounds[:, side].copy()
    threshold = f"tol {tol:.1e}" + ("" if precision is None else
                                    f" and {precision:.0e} of the lower bound")
    message = (
        f"gap ({gap}) {width:.3e} {'<' if status == Status.OPTIMAL else '>='} {threshold} "
        f"after {budget.iterations} iterations"
        + ("" if budget.stopped is not Status.TIME_LIMIT else f" (time limit {time_limit} s)")
    )
    logger.info("interval iteration: %s, %.3fs", message, seconds)
    return IterationResult(
        status=status,
        held_lower=lower,
        held_upper=upper,
        value_lower=entry(lower, mdp.initial),
        value_upper=entry(upper, mdp.initial),
        iterations=budget.iterations,
        seconds=seconds,
        greedy=lambda: lift_policy(mdp, q, greedy_choices(q, known) if n else
                                   np.zeros(0, int)),
        message=message,
    )
