"""The optimum of a reachability objective in rational arithmetic: a floating-point
policy made exact (Giro's "exact solutions from a floating-point scheduler").

Given the MDP's transition probabilities as rationals (:mod:`mitld_lp.exact.rows`), a
target and a sense (``"max"`` or ``"min"``), and a policy (the float solvers'):

1. **The states decided 0 by the graph**: for max, those from which no path reaches the
   target (``Pmax = 0``); for min, those from which some policy avoids the target
   forever (``Pmin = 0``, the greatest set whose states all have a choice staying in
   it).  After them no end component is left among the other states under min.
2. **Evaluate** the policy exactly: on its chain, the states that cannot reach the
   target are 0; the others solve ``v = P v + b`` (``b``: the one-step probability of
   the target), strongly connected block by block, successors first.  A single state is
   one division (``v(s) = (b + sum_{j != s} p_j v_j) / (1 - p_ss)``); an acyclic part
   needs nothing else; a cyclic block is one rational linear solve (python-flint's
   ``fmpq_mat.solve``).
3. **Check** every choice of every undecided state against those values,
   ``E_c(v) = sum_j p_j v_j``: max, none above ``v(s)``; min, none below.  Where one is,
   switch to the best choice (strictly better only: ties keep the policy) and go to 2.

Why the result is the optimum.  Max: ``v`` is a policy's value, so ``v <= Pmax``; no
choice improves it, so ``v`` is a fixed point of the Bellman operator, and ``Pmax`` is its
least fixed point: ``v >= Pmax``.  Min: ``v >= Pmin`` as a policy's value, and once the
``Pmin = 0`` states are set the Bellman operator has one fixed point on the rest (no end
component is left there), which ``v`` is.  Each switch strictly raises (max) or lowers
(min) the value where it is made and nowhere moves it the other way (the usual argument
of policy iteration; under max a strictly better switch cannot close a cycle of positive
value that leaves no way to the target), so the iteration ends, from the float policy
usually after its first evaluation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.exact.errors import ExactTooLarge, TimeUp
from mitld_lp.mdp import MDP
from mitld_lp.solvers.graph import backward_reachable, graph_blocks
from mitld_lp.solvers.quotient import prob0_max

__all__ = ["ExactSolution", "avoid_forever", "solve_exact", "chain_blocks"]


@dataclass(frozen=True, slots=True, eq=False)
class ExactSolution:
    """The exact optimum in every state (``values``, python-flint ``fmpq``: 1 on the
    target, 0 where the graph decides 0), a policy that attains it (``policy``: the start
    policy with the switches made), the policy evaluations it took (``rounds``) and the
    states whose choice was switched (``switched``)."""

    values: tuple[Any, ...]
    policy: np.ndarray
    rounds: int
    switched: int


def avoid_forever(mdp: MDP, target: np.ndarray) -> np.ndarray:
    """``(n_states,)`` bool: the states from which some policy never reaches ``target``
    (``Pmin = 0``): the greatest set of non-target states each with a choice whose
    successors all lie in the set."""
    keep = ~np.asarray(target, dtype=bool)
    m = mdp.matrix
    owner = np.repeat(np.arange(mdp.n_choices), np.diff(m.indptr))
    while True:
        leaving = np.bincount(owner, weights=~keep[m.indices], minlength=mdp.n_choices) > 0
        staying = np.logical_or.reduceat(~leaving, mdp.row_groups[:-1])
        now = keep & staying
        if np.array_equal(now, keep):
            return keep
        keep = now


def chain_blocks(mdp: MDP, policy: np.ndarray, states: np.ndarray) -> np.ndarray:
    """The sizes of the cyclic strongly connected blocks of ``policy``'s chain on the
    ``states`` (bool mask): what an exact evaluation factorises."""
    idx = np.flatnonzero(states)
    if not idx.size:
        return np.zeros(0, dtype=np.int64)
    m = mdp.matrix
    rows = policy[idx]
    local = np.full(mdp.n_states, -1, dtype=np.int64)
    local[idx] = np.arange(idx.size)
    counts = m.indptr[rows + 1] - m.indptr[rows]
    src = np.repeat(np.arange(idx.size), counts)
    dst = local[np.concatenate([m.indices[m.indptr[c]:m.indptr[c + 1]] for c in rows])]
    inside = dst >= 0
    graph = sp.csr_array((np.ones(int(inside.sum()), dtype=bool), (src[inside], dst[inside])),
                         shape=(idx.size, idx.size))
    blocks = graph_blocks(graph, np.zeros(0))
    return blocks.size[blocks.size > 1]


class _Solver:
    def __init__(self, mdp: MDP, values: list[Any], target: np.ndarray, zero: np.ndarray,
                 max_block: int, deadline: float) -> None:
        from flint import fmpq, fmpq_mat

        self.fmpq, self.fmpq_mat = fmpq, fmpq_mat
        self.mdp, self.p, self.target, self.zero = mdp, values, target, zero
        self.maybe = ~target & ~zero
        self.indptr = [int(x) for x in mdp.matrix.indptr]
        self.indices = [int(x) for x in mdp.matrix.indices]
        self.max_block, self.deadline = max_block, deadline

    def _clock(self) -> None:
        if time.perf_counter() > self.deadline:
            raise TimeUp

    def entries(self, c: int) -> tuple[list[int], list[Any]]:
        lo, hi = self.indptr[c], self.indptr[c + 1]
        return self.indices[lo:hi], self.p[lo:hi]

    def evaluate(self, policy: np.ndarray) -> list[Any]:
        """The policy's exact values (module docs, step 2)."""
        fmpq, n = self.fmpq, self.mdp.n_states
        v = [fmpq(1) if t else fmpq(0) for t in self.target.tolist()]
        maybe = np.flatnonzero(self.maybe)
        src, dst = [], []
        for s in maybe.tolist():
            cols, _ = self.entries(int(policy[s]))
            src += [s] * len(cols)
            dst += cols
        can = backward_reachable(n, np.asarray(src, dtype=np.int64),
                                 np.asarray(dst, dtype=np.int64), self.target)
        solve = self.maybe & can
        idx = np.flatnonzero(solve)
        if not idx.size:
            return v
        local = np.full(n, -1, dtype=np.int64)
        local[idx] = np.arange(idx.size)
        edges = [(int(local[s]), int(local[j])) for s, j in zip(src, dst, strict=True)
                 if solve[s] and solve[j]]
        graph = sp.csr_array((np.ones(len(edges), dtype=bool),
                              ([a for a, _ in edges], [b for _, b in edges])),
                             shape=(idx.size, idx.size))
        blocks = graph_blocks(graph, np.zeros(0))
        for level in blocks.walk():
            self._clock()
            for k in level.single.tolist():
                s = int(idx[k])
                cols, ps = self.entries(int(policy[s]))
                num, stay = fmpq(0), fmpq(0)
                for j, p in zip(cols, ps, strict=True):
                    if j == s:
                        stay += p
                    else:
                        num += p * v[j]
                v[s] = num / (1 - stay)
            comps = blocks.component[level.rest]
            for comp in np.unique(comps).tolist():
                self._block([int(idx[k]) for k in level.rest[comps == comp].tolist()],
                            policy, v)
        return v

    def _block(self, states: list[int], policy: np.ndarray, v: list[Any]) -> None:
        """``(I - P_BB) x = P_B,out v`` for one cyclic block ``B``, exactly."""
        k = len(states)
        if k > self.max_block:
            raise ExactTooLarge(
                f"exact answer: the policy's chain has a cyclic block of {k:,} states, more "
                f"than the {self.max_block:,} an exact solve factorises "
                "(mitld_lp.defaults.EXACT_MAX_BLOCK)")
        at = {s: i for i, s in enumerate(states)}
        a = self.fmpq_mat(k, k)
        rhs = self.fmpq_mat(k, 1)
        for i, s in enumerate(states):
            a[i, i] = 1
            cols, ps = self.entries(int(policy[s]))
            out = self.fmpq(0)
            for j, p in zip(cols, ps, strict=True):
                if j in at:
                    a[i, at[j]] = a[i, at[j]] - p
                else:
                    out += p * v[j]
            rhs[i, 0] = out
        x = a.solve(rhs)
        for i, s in enumerate(states):
            v[s] = x[i, 0]

    def improve(self, policy: np.ndarray, v: list[Any], sense: str) -> int:
        """Switch each undecided state to its best choice where that is strictly better
        than ``v`` (module docs, step 3); the number of switches."""
        switched = 0
        groups = self.mdp.row_groups.tolist()
        for s in np.flatnonzero(self.maybe).tolist():
            self._clock()
            best, arg = v[s], -1
            for c in range(groups[s], groups[s + 1]):
                cols, ps = self.entries(c)
                q = self.fmpq(0)
                for j, p in zip(cols, ps, strict=True):
                    q += p * v[j]
                if (q > best) if sense == "max" else (q < best):
                    best, arg = q, c
            if arg >= 0 and arg != policy[s]:
                policy[s] = arg
                switched += 1
        return switched


def solve_exact(mdp: MDP, values: list[Any], target: np.ndarray, sense: str,
                policy: np.ndarray, *, max_block: int, deadline: float = float("inf"),
                ) -> ExactSolution:
    """The exact optimum (``sense`` ``"max"`` or ``"min"``) of reaching ``target`` on
    ``mdp`` with the exact transition probabilities ``values`` (one ``fmpq`` per entry of
    ``mdp.matrix``, needed in the rows of the undecided states), from ``policy`` (a
    choice per state; module docs).  Raises :class:`ExactTooLarge` before factorising a
    cyclic block of more than ``max_block`` states, :class:`TimeUp` past ``deadline``
    (``time.perf_counter``)."""
    if sense not in ("max", "min"):
        raise ValueError(f"sense: 'max' or 'min', got {sense!r}")
    target = np.asarray(target, dtype=bool)
    zero = prob0_max(mdp, target) if sense == "max" else avoid_forever(mdp, target)
    solver = _Solver(mdp, values, target, zero, max_block, deadline)
    policy = np.array(policy, dtype=np.int64)
    start = policy.copy()
    groups = mdp.row_groups
    undecided = np.flatnonzero(solver.maybe)
    bad = undecided[(policy[undecided] < groups[undecided]) |
                    (policy[undecided] >= groups[undecided + 1])]
    if bad.size:
        raise ValueError(f"policy: no choice of its own at states {bad[:10].tolist()}")
    rounds = 0
    while True:
        v = solver.evaluate(policy)
        rounds += 1
        if not solver.improve(policy, v, sense):
            break
    return ExactSolution(tuple(v), policy, rounds, int(np.count_nonzero(policy != start)))
