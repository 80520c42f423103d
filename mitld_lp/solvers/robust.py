r"""Robust interval iteration: the max over the robot of the min over nature of the
probability of reaching the target, bracketed from both sides.

The robust Bellman operator of a :class:`~.robust_graph.RobustGame` is

.. math::

    (B V)(s) = \max_{c \in Act(s)} \; \min_{v \in Rows(c)} \; P_v \cdot V,

nature's rows being the vertex distributions of the hazard box
(:func:`mitld_lp.product.imdp.vertex_rows`: the inner minimum over the box of a multilinear
function is attained at a vertex).  The robust value ``V*`` is its least fixed point with
``V = 1`` on the target.

* **Graph first** (:mod:`.robust_graph`): ``V* = 0`` outside the positive attractor,
  ``V* = 1`` on the almost-sure set; both are fixed before any number is computed.
* **Level by level**: the strongly connected blocks of the support graph are solved
  downstream first; a block's values are final (to ``tol``) before its predecessors start.
* **Two sequences**: ``L`` from 0 and ``U`` from 1 under ``B``; ``L`` rises to ``V*``.
  ``U`` alone may stop above ``V*`` in an end component that nature can keep the play in;
  it is *deflated* (Kelmendi, Kramer, Kretinsky, Weininger, CAV 2018: bounded value
  iteration for simple stochastic games): in each maximal end component of the block
  when nature uses only its rows optimal for ``L``, no state is worth more than the best
  exit the robot has, ``U(s) <- min(U(s), max_{exits c} min_v P_v . U)``.  The iteration
  stops when ``U - L <= tol`` on the block, so ``[L(s), U(s)]`` brackets ``V*(s)``.
* **Solves for slow blocks**: a block left only by rare steps closes at about their
  probability per sweep.  A Markov-chain block is solved directly; in others the values
  of the rows greedy for ``L`` (or ``U``) are solved for (:meth:`_Block.jump`) and kept
  where sound: for ``L`` when the block has no nature's choice, for ``U`` when they are
  a pre-fixed point of ``B`` (above the least fixed point, Knaster-Tarski).

:func:`robust_policy` reads a robot policy off ``L`` (near-optimal choices, and among them
ones that make progress against every nature: the positive attractor restricted to them);
its own robust value is computed by running the same iteration on the game it leaves
(:meth:`~.robust_graph.RobustGame.restrict`) or exactly by the LP of
:mod:`.robust_lp`; :func:`bellman_residual` checks it is a fixed point of ``B``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from mitld_lp import defaults
from mitld_lp.solvers.result import Status, read_only
from mitld_lp.solvers.robust_graph import (
    RobustGame,
    almost_sure,
    end_components,
    gather,
    levels,
    positive_attractor,
    take_rows,
)

__all__ = ["RobustIteration", "robust_interval_iteration", "robust_policy", "bellman",
           "bellman_residual", "sweep_budget"]

DEFLATE_EVERY = 16
"""Sweeps of a block between two deflations of its upper bound."""

MAX_SWEEPS = 10_000_000
"""Sweeps over all blocks after which the iteration stops (status ``MAX_ITERATIONS``)."""

WORK = 2e8
"""The work (nonzeros read, a sweep's own overhead counted as :data:`SWEEP_COST` of
them) of an iteration given :func:`sweep_budget`: some seconds."""

JUMP_SLACK = 1e-13
"""How far ``B u`` may exceed ``u`` (rounding of a sparse solve) for :meth:`_Block.jump`
to take ``u`` as an upper bound."""

JUMP_STATES = 20_000
"""The largest block whose values :meth:`_Block.jump` solves for directly."""

SWEEP_COST = 4000
"""A sweep's fixed overhead in nonzeros read (numpy calls on a small block)."""


def sweep_budget(game: RobustGame, work: float = WORK) -> int:
    """The sweeps of :func:`robust_interval_iteration` on ``game`` that fit in ``work``,
    estimated before it starts (each sweep reading at most every row once): for callers
    with no time limit, so that a block converging slowly ends with a status
    (``MAX_ITERATIONS``, the bracket still sound) rather than running for hours."""
    per_sweep = float(game.matrix.nnz) + SWEEP_COST
    return int(min(MAX_SWEEPS, max(DEFLATE_EVERY, work // per_sweep)))


@dataclass(frozen=True, slots=True, eq=False)
class RobustIteration:
    """The bracket of robust interval iteration: ``lower <= V* <= upper`` on every state
    (read-only arrays); ``prob0`` (``V* = 0``) and ``prob1`` (``V* = 1``, the target
    included) from the graph; ``sweeps`` applications of ``B`` to a block."""

    status: Status
    lower: np.ndarray
    upper: np.ndarray
    prob0: np.ndarray
    prob1: np.ndarray
    sweeps: int
    message: str


def bellman(game: RobustGame, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(choice_values, state_values)``: ``min_v P_v . V`` per choice and
    ``max_c`` of that per state."""
    q = game.matrix @ v
    cmin = np.minimum.reduceat(q, game.vertex_groups[:-1])
    return cmin, np.maximum.reduceat(cmin, game.row_groups[:-1])


class _Block:
    """The states of one level with their choices' rows: global columns for the Bellman
    operator, and (made when first needed) a local game for the end components, with
    one extra state standing for everything outside the level."""

    def __init__(self, game: RobustGame, states: np.ndarray) -> None:
        self.states = states
        choices = gather(game.row_groups[states], game.row_groups[states + 1])
        self.row_groups = np.zeros(states.size + 1, dtype=np.int64)
        np.cumsum(np.diff(game.row_groups)[states], out=self.row_groups[1:])
        rows = gather(game.vertex_groups[choices], game.vertex_groups[choices + 1])
        self.vertex_groups = np.zeros(choices.size + 1, dtype=np.int64)
        np.cumsum(np.diff(game.vertex_groups)[choices], out=self.vertex_groups[1:])
        self.matrix = take_rows(game.matrix, rows, game.n_states)
        self.game = RobustGame(self.matrix, self.vertex_groups, self.row_groups)
        local = np.full(game.n_states, states.size, dtype=np.int64)
        local[states] = np.arange(states.size)
        self._local_of = local
        self._local: RobustGame | None = None
        cols = local[self.matrix.indices]
        own = np.repeat(np.arange(states.size),
                        np.diff(self.row_groups))[np.repeat(np.arange(choices.size),
                                                            np.diff(self.vertex_groups))]
        entry_state = np.repeat(own, np.diff(self.matrix.indptr))
        self.cyclic = bool(states.size > 1 or np.any(cols == entry_state))
        # one choice of one row per state: a Markov chain, solved rather than iterated
        self.chain = bool(self.cyclic and choices.size == states.size
                          and rows.size == choices.size)
        # every choice one row (no nature to answer): any choice's value is below B's
        self.robot_only = bool(rows.size == choices.size)

    def evaluate(self, row: np.ndarray, values: np.ndarray) -> np.ndarray:
        """The reachability values of the block's states when state ``i`` plays its
        local row ``row[i]`` for ever, given ``values`` outside the block: the solution
        of ``(I - P_BB) x = P_B,out . values`` on the states that leave the block with
        positive probability, 0 on the others (they never leave).  A block left only by
        rare steps takes ``B`` about the inverse of their probability in sweeps; this
        is one sparse solve."""
        m = self.states.size
        mat = take_rows(self.matrix, row, self.matrix.shape[1]).tocoo()
        cols = self._local_of[mat.col]
        inner = cols < m
        p_bb = sp.csr_array((mat.data[inner], (mat.row[inner], cols[inner])), shape=(m, m))
        leak = np.bincount(mat.row[~inner], weights=mat.data[~inner], minlength=m) > 0
        support = sp.csr_array((np.ones(int(inner.sum())), (cols[inner], mat.row[inner])),
                               shape=(m, m))  # reversed edges
        leaves = leak.copy()
        frontier = leak.copy()
        while frontier.any():
            frontier = (support @ frontier.astype(np.float64) > 0) & ~leaves
            leaves |= frontier
        outside = np.asarray(values, dtype=np.float64).copy()
        outside[self.states] = 0.0
        rhs = np.asarray(sp.csr_array(take_rows(self.matrix, row, self.matrix.shape[1]))
                         @ outside)
        x = np.zeros(m)
        keep = np.flatnonzero(leaves)
        if keep.size:
            # each row read as summing to 1: the diagonal of I - P_BB is what the row
            # gives elsewhere, not 1 - p_ii (which loses the digits of a rare exit)
            inside = p_bb[keep][:, keep]
            diag = inside.diagonal()
            away = np.bincount(mat.row, weights=mat.data, minlength=m)[keep] - diag
            sub = sp.csc_array(sp.diags_array(away) - (inside - sp.diags_array(diag)))
            x[keep] = np.atleast_1d(spla.spsolve(sub, rhs[keep]))
        return np.clip(np.nan_to_num(x, nan=0.0), 0.0, 1.0)

    def greedy_rows(self, values: np.ndarray) -> np.ndarray:
        """Per block state the local row of its best choice against nature's best row
        for ``values`` (the first of equals)."""
        q = self.matrix @ values
        vg, rg = self.vertex_groups, self.row_groups
        rows = np.arange(q.size)
        cmin = np.minimum.reduceat(q, vg[:-1])
        rc = self.game.row_choice()
        nat = np.minimum.reduceat(np.where(q == cmin[rc], rows, q.size), vg[:-1])
        cs = self.game.choice_state()
        best = np.maximum.reduceat(cmin, rg[:-1])
        ch = np.arange(cmin.size)
        pick = np.minimum.reduceat(np.where(cmin == best[cs], ch, cmin.size), rg[:-1])
        return nat[pick]

    def jump(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Move both bounds to the values of the rows greedy for them (:meth:`evaluate`)
        where that is sound: ``lower`` when the block has no nature's choice (a policy's
        value is at most the best); ``upper`` when the candidate is a pre-fixed point of
        ``B`` (``B u <= u``, to rounding: every such ``u`` is above the least fixed
        point, Knaster-Tarski)."""
        s = self.states
        if self.robot_only:
            lower[s] = np.maximum(lower[s], self.evaluate(self.greedy_rows(lower), lower))
        for guide in (lower, upper):
            cand = upper.copy()
            cand[s] = np.maximum(self.evaluate(self.greedy_rows(guide), upper), lower[s])
            if (bellman(self.game, cand)[1] <= cand[s] + JUMP_SLACK).all():
                upper[s] = np.minimum(upper[s], cand[s])
                return

    def local(self) -> RobustGame:
        if self._local is None:
            m = self.states.size
            rows_n = int(self.vertex_groups[-1])
            cols = self._local_of[self.matrix.indices]
            mat = sp.csr_array((np.concatenate([self.matrix.data, [1.0]]),
                                np.concatenate([cols, [m]]),
                                np.concatenate([self.matrix.indptr,
                                                [self.matrix.indptr[-1] + 1]])),
                               shape=(rows_n + 1, m + 1))
            self._local = RobustGame(
                mat,
                np.concatenate([self.vertex_groups, [self.vertex_groups[-1] + 1]]),
                np.concatenate([self.row_groups, [self.row_groups[-1] + 1]]),
            )
        return self._local

    def deflate(self, lower: np.ndarray, upper: np.ndarray) -> None:
        """Cap ``upper`` on every end component nature can keep (module docstring)."""
        local = self.local()
        q_lo = self.matrix @ lower
        cmin_lo = np.minimum.reduceat(q_lo, self.vertex_groups[:-1])
        row_choice = self.game.row_choice()
        best = q_lo <= cmin_lo[row_choice] + 1e-12 * np.maximum(1.0, np.abs(cmin_lo[row_choice]))
        m = self.states.size
        inside = np.ones(m + 1, dtype=bool)
        inside[m] = False
        label, staying = end_components(local, inside, np.concatenate([best, [False]]))
        label, staying = label[:m], staying[:-1]
        in_ec = label >= 0
        if not in_ec.any():
            return
        cmin_up = np.minimum.reduceat(self.matrix @ upper, self.vertex_groups[:-1])
        c_state = self.game.choice_state()
        exits = ~staying & in_ec[c_state]
        comp = label[c_state[exits]]
        best_exit = np.zeros(int(label.max()) + 1)
        np.maximum.at(best_exit, comp, cmin_up[exits])
        s = self.states[in_ec]
        upper[s] = np.minimum(upper[s], best_exit[label[in_ec]])


def robust_interval_iteration(
    game: RobustGame,
    target: np.ndarray,
    *,
    tol: float = defaults.TOL,
    max_sweeps: int = MAX_SWEEPS,
    time_limit: float | None = None,
) -> RobustIteration:
    """Bracket the robust value ``max_robot min_nature P(reach target)`` of every state
    within ``tol`` (module docstring).  Never raises on a limit: the status says
    ``MAX_ITERATIONS`` or ``TIME_LIMIT`` and the bracket is still sound."""
    start = time.perf_counter()
    target = np.asarray(target, dtype=bool)
    positive, _ = positive_attractor(game, target)
    prob1 = almost_sure(game, target, positive)
    lower = np.where(prob1, 1.0, 0.0)
    upper = np.where(positive, 1.0, 0.0)
    todo = positive & ~prob1
    sweeps, status, message = 0, Status.OPTIMAL, ""
    for states in levels(game, todo):
        block = _Block(game, states)
        if block.chain:  # its one row per state: the values given the outside's
            only = np.zeros(states.size, dtype=np.int64) + np.arange(states.size)
            lower[states] = np.maximum(lower[states], block.evaluate(only, lower))
            upper[states] = np.maximum(np.minimum(upper[states], block.evaluate(only, upper)),
                                       lower[states])
            sweeps += 1
            continue
        while True:
            for _ in range(DEFLATE_EVERY):
                lower[states] = np.maximum(lower[states], bellman(block.game, lower)[1])
                upper[states] = np.minimum(upper[states], bellman(block.game, upper)[1])
                sweeps += 1
                if float(np.max(upper[states] - lower[states])) <= tol:
                    break
            if float(np.max(upper[states] - lower[states])) <= tol:
                break
            if block.cyclic:
                block.deflate(lower, upper)
                if states.size <= JUMP_STATES:
                    block.jump(lower, upper)
            if sweeps >= max_sweeps:
                status, message = Status.MAX_ITERATIONS, f"stopped after {sweeps} sweeps"
                break
            if time_limit is not None and time.perf_counter() - start > time_limit:
                status, message = Status.TIME_LIMIT, f"time limit {time_limit:g} s reached"
                break
        if status is not Status.OPTIMAL:
            break
    gap = float(np.max(upper - lower)) if upper.size else 0.0
    if status is Status.OPTIMAL:
        message = f"converged: gap {gap:.2e} <= {tol:g} after {sweeps} block sweeps"
    return RobustIteration(status, read_only(lower), read_only(upper), read_only(~positive),
                           read_only(prob1), sweeps, message)


def robust_policy(
    game: RobustGame, target: np.ndarray, lower: np.ndarray, *, tie: float
) -> np.ndarray:
    """A robot policy (a choice per state) from a lower bound ``lower`` on the robust
    value: among the choices within ``tie`` of the best ``min_v P_v . lower``, one by
    which the state enters the positive attractor of those choices (so that no nature
    can hold the play in a loop the values alone would allow); elsewhere the first best
    choice."""
    cmin, best = bellman(game, np.asarray(lower, dtype=np.float64))
    c_state = game.choice_state()
    near = cmin >= best[c_state] - tie
    _, via = positive_attractor(game, np.asarray(target, dtype=bool), allowed=near)
    top = np.flatnonzero(cmin >= best[c_state])
    states, first = np.unique(c_state[top], return_index=True)
    policy = np.empty(game.n_states, dtype=np.int64)
    policy[states] = top[first]
    return np.where(via >= 0, via, policy)


def bellman_residual(game: RobustGame, target: np.ndarray, values: np.ndarray) -> float:
    """``max_s |(B V)(s) - V(s)|`` over the states outside ``target``: 0 for a fixed
    point of the robust operator."""
    _, bv = bellman(game, values)
    off = ~np.asarray(target, dtype=bool)
    return float(np.max(np.abs(bv[off] - values[off]))) if off.any() else 0.0
