"""The compiled blocks' early jump decided from the block itself (:data:`mitld_lp.solvers.
iteration._EARLY`): what the policy jump would cost against the sweeps it would save,
both in one unit, *entries touched* (one stored entry of the block's rows read once by a
compiled Gauss--Seidel sweep), computed from the block's structure before the work.
No clock is read: the same block and the same bounds give the same decision, the same
jump and the same bits on an idle machine and on a loaded one.

**A sweep** touches the block's entries and its choices (their exit rewards):
``inner.nnz + choices`` (:attr:`Cost.sweep`).  Measured at 6.3-9.9 ns an entry on the
bus and consensus blocks below (one sweep 1.6-13 ms).

**A round** of policy iteration (one LU of the policy's chain, its refined solves, the
look-ahead's Bellman sweeps and the next greedy policy; :mod:`mitld_lp.solvers.
policy_jump`) costs :data:`ROUND_STATE` entries a state (SuperLU's ordering and symbolic
work, the solves), :data:`ROUND_FLOP` a multiply of the LU's numeric factorisation
(:func:`lu_flops`: the fill) and :data:`ROUND_ENTRY` per entry of the block's rows (the
look-ahead's sweeps and the scores in extended precision) (:attr:`Cost.round`).  The
LU's multiplies are counted on the chain of the policy the jump starts from (its
pattern, the diagonal pivoted on as :func:`~mitld_lp.solvers.topological.chain_lu`
does): exactly up to :data:`SAMPLE` states, else on breadth-first balls of
``SAMPLE / 4`` and ``SAMPLE`` states of the block and extrapolated at the growth the
two show (a grid's LU fills more per state the larger it is, a chain's does not).
Every choice's pattern at once would not do: on ``consensus`` it fills a hundred
thousand times more than a policy's.

**Rounds** (:attr:`Cost.rounds`): ``1 + depth / (AHEAD_SWEEPS + 1)``, the depth of the
block's state graph (the eccentricity found by two breadth-first searches): each round
carries an improvement at least ``AHEAD_SWEEPS + 1`` steps, as its look-ahead does.

The jump is started where ``rounds * round <= SHARE * saved * sweep`` (:func:`worth`,
:data:`SHARE` a half: the forecast must leave a margin, module docs below), and once
started it is abandoned before a round of policy iteration that would take it past
``saved * sweep / round`` rounds (:attr:`Cost.allowance`), the rounds left forecast from
how fast the switches fall (:func:`mitld_lp.solvers.policy_jump.improve_ahead`).

Calibrated once on this machine (2 cores; CPU seconds of ``time.process_time`` in
diagnostic runs at a load average of 2-8, 2026-11-30), on the blocks the early look
stops: QVBS ``consensus`` 6-2 ``c2`` (87,225, 139,566 and 93,067 states; 4-5 LUs a
jump; depth 49-51; LUs of 0.07-0.40 s with 4 multiplies a state, i.e. the ordering's
1-3 us a state; a whole round 0.31-0.63 s) and ``bus_scaled`` n128 d3 (32,768 and
16,384 states, grids of depth 254; LUs of 0.14-0.17 s and 0.06 s with 1,500 and 425
multiplies a state, 3.4-8.5 ns a multiply; a round 0.22 and 0.095 s).  A round in
sweeps of its block, measured (modelled): consensus 41 (56), 48 (48), 50 (41); bus 63
and 57 (49 and 49, the LU's multiplies sampled: 280-300 a state against the 425-1,500 a
policy's full LU makes).  The model then jumps the
three consensus blocks (about 5.5 rounds against 400-700 sweeps saved: the jumps took
4-5 LUs) and refuses both bus blocks (24 rounds of about 50 sweeps against 968 and 468:
policy iteration switched 9,495, 9,187, ... and 2,950, 3,232 states a round there, 18
rounds went by in the first block without a fixpoint).  The estimate costs 30-40 ms a
block there and 65-110 ms on consensus's (the state graph made symmetric, two searches,
two sampled LUs).

**The margin** (:data:`SHARE`).  A jump refused costs at most the sweeps it would have
saved; one started and abandoned costs its rounds on top of all those sweeps, so a
forecast near the saving is a poor bet.  And the model errs short on blocks like the
bus grids: a round measured 57-77 sweeps there (45-50 modelled: a compiled sweep of a
grid touches an entry in 3 ns, the calibration's 6-10), and the rounds run long where
policy iteration's switches fall slowly.  On ``bus_scaled`` n64 d3 the block of 8,192
states (depth 126) was forecast 12.5 rounds of 45.6 sweeps, 570 sweeps, against 629
saved: started, its switches fell 2,679 -> 2,483 in two rounds (103 more forecast) and
it was abandoned, 0.056 s spent.  With the margin it is refused up front; consensus
6-2 ``c2``'s three blocks, forecast 226-303 sweeps against 968 saved (0.23-0.31 of the
saving), are jumped as before (4-5 LUs each)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers.policy_jump import AHEAD_SWEEPS
from mitld_lp.solvers.topological import Block

__all__ = ["Cost", "ROUND_ENTRY", "ROUND_FLOP", "ROUND_STATE", "SAMPLE", "SHARE",
           "block_depth", "cost", "lu_flops", "worth"]

ROUND_STATE = 400.0
"""Entries a state that a round of policy iteration costs besides the LU's multiplies
(module docs: 1-3 us a state over 7-10 ns an entry)."""
ROUND_FLOP = 0.5
"""Entries a multiply of the LU's numeric factorisation costs (3.4-8.5 ns)."""
ROUND_ENTRY = 20.0
"""Entries a round costs per entry of the block's rows (11 look-ahead sweeps in NumPy,
the scores and residuals in extended precision)."""
SHARE = 0.5
"""The share of the saved sweeps' cost that a jump's forecast may reach and still be
started (module docs: the margin)."""
SAMPLE = 4096
"""The largest state graph whose LU is counted exactly (a few ms); above, balls of
``SAMPLE / 4`` and ``SAMPLE`` states are counted and extrapolated."""
LOOK_AHEAD = AHEAD_SWEEPS + 1
"""Steps a round carries an improvement: the look-ahead's
:data:`~mitld_lp.solvers.policy_jump.AHEAD_SWEEPS` Bellman sweeps and the greedy step."""


@dataclass(frozen=True, slots=True)
class Cost:
    """A block's costs in entries touched (module docs)."""

    sweep: float
    """Entries a compiled sweep of the block touches."""
    round: float
    """Entries a round of policy iteration touches (its LU included)."""
    rounds: float
    """Rounds of policy iteration forecast for the jump."""
    depth: int
    """The depth of the block's state graph."""
    flops: float
    """The multiplies of an LU of the block's state graph (counted or extrapolated)."""

    def allowance(self, saved: float) -> float:
        """The rounds of policy iteration that cost what ``saved`` sweeps do."""
        return saved * self.sweep / self.round


def worth(c: Cost, saved: float) -> bool:
    """Whether the forecast jump costs at most :data:`SHARE` of the ``saved`` sweeps
    (module docs)."""
    return c.rounds * c.round <= SHARE * saved * c.sweep


def cost(block: Block, chosen: np.ndarray, saved: float | None = None) -> Cost:
    """The block's :class:`Cost` for a jump from the policy ``chosen`` (local choice
    indices, one a state), a function of the block's structure alone (module docs).
    ``saved``: where the cost without the LU's multiplies (a lower bound: they are
    counted at least 0) is already not :func:`worth` those sweeps, that is returned,
    ``flops`` NaN, the LU not counted (the same decision, the samples' LUs spared)."""
    graph = _state_graph(block)
    n = graph.shape[0]
    depth, order = _depth(graph)
    entries = float(block.inner.nnz)
    sweep = entries + float(block.choices.shape[0])
    rounds = 1.0 + depth / LOOK_AHEAD
    floor = ROUND_STATE * n + ROUND_ENTRY * entries
    if saved is not None:
        least = Cost(sweep=sweep, round=floor, rounds=rounds, depth=depth,
                     flops=float("nan"))
        if not worth(least, saved):
            return least
    chain = sp.csr_array(block.inner[chosen])
    if n <= SAMPLE:
        flops = lu_flops(chain)
    else:
        small = lu_flops(_ball(chain, order, SAMPLE // 4)) / (SAMPLE // 4)
        large = lu_flops(_ball(chain, order, SAMPLE)) / SAMPLE
        growth = 0.0 if small <= 0.0 or large <= 0.0 else float(
            np.clip(np.log(large / small) / np.log(4.0), 0.0, 1.0))
        flops = large * n * (n / SAMPLE) ** growth
    return Cost(sweep=sweep, round=floor + ROUND_FLOP * flops, rounds=rounds,
                depth=depth, flops=flops)


def block_depth(block: Block) -> int:
    """The depth of the block's state graph (:func:`_depth`; the sweeps' gate,
    :mod:`mitld_lp.solvers.sweep_gate`)."""
    return _depth(_state_graph(block))[0]


def _state_graph(block: Block) -> sp.csr_array:
    """``(n, n)`` pattern of the block without directions: ``s - s'`` if a choice of
    ``s`` may move to ``s'`` inside the block or one of ``s'`` to ``s``.  A state's
    choices are consecutive rows, so its entries are read in place.  Its entries are
    booleans (the pattern is all the searches read: :func:`_depth`'s are unweighted), a
    byte an entry where float64 ones were eight, through the transpose and the sum."""
    n = block.states.size
    inner = block.inner
    moves = sp.csr_array((np.ones(inner.nnz, dtype=bool), inner.indices,
                          inner.indptr[block.groups]), shape=(n, n))
    return sp.csr_array(moves + moves.T)


SEARCHES = 8
"""At most this many components of a block are searched for its largest (module docs of
:func:`_depth`)."""


def _depth(graph: sp.csr_array) -> tuple[int, np.ndarray]:
    """The eccentricity of the far end of a breadth-first search in the block's largest
    component (``graph`` without directions; a block may hold several components of one
    level, and its rounds are its largest's: searched from the first state not reached
    yet, at most :data:`SEARCHES` times, until no unreached part could be larger), a
    lower bound of that component's diameter, exact on grids and trees; and the states
    by their distance from where that component's search began (the samples' balls;
    other components' states last)."""
    from scipy.sparse.csgraph import dijkstra

    n = graph.shape[0]
    if n == 0:
        return 0, np.zeros(0, dtype=np.int64)
    seen = np.zeros(n, dtype=bool)
    best, first = -1, np.zeros(0)
    for _ in range(SEARCHES):
        source = int(np.argmin(seen))
        dist = dijkstra(graph, directed=True, indices=source, unweighted=True)
        reached = np.isfinite(dist)
        seen |= reached
        size = int(np.count_nonzero(reached))
        if size > best:
            best, first = size, dist
        if n - int(np.count_nonzero(seen)) <= best:
            break
    far = int(np.argmax(np.where(np.isfinite(first), first, -1.0)))
    second = dijkstra(graph, directed=True, indices=far, unweighted=True)
    depth = int(np.max(second[np.isfinite(second)]))
    return depth, np.argsort(first, kind="stable")  # unreached (inf) last


def _ball(chain: sp.csr_array, order: np.ndarray, m: int) -> sp.csr_array:
    """The policy's chain on the first ``m`` states of the breadth-first ``order``."""
    keep = np.sort(order[:m])
    return sp.csr_array(chain[keep][:, keep])


def lu_flops(graph: sp.csr_array) -> float:
    """The multiplies of SuperLU's LU of ``I - Q`` (``Q``: ``graph``'s pattern, each row
    scaled to 1/2, so the diagonal is pivoted on; a state's entry on itself merged into
    the diagonal), in the order
    :func:`~mitld_lp.solvers.topological.chain_lu` uses: the sum over the pivots of the
    entries below it in ``L`` times those right of it in ``U``."""
    import scipy.sparse.linalg as spla

    n = graph.shape[0]
    if n == 0:
        return 0.0
    pattern = sp.csr_array(graph, copy=True)
    pattern.sum_duplicates()
    pattern.data[:] = 1.0
    out = np.diff(pattern.indptr).astype(np.float64)
    q = sp.csr_array(sp.diags_array(0.5 / np.maximum(out, 1.0)) @ pattern)
    a = sp.csc_array(sp.eye_array(n, format="csc") - q)
    lu = spla.splu(a, permc_spec="MMD_AT_PLUS_A", options={"SymmetricMode": True})
    below = np.diff(sp.csc_array(lu.L).indptr).astype(np.float64) - 1.0  # unit diagonal
    right = np.diff(sp.csr_array(lu.U).indptr).astype(np.float64) - 1.0
    return float(np.sum(below * right))
