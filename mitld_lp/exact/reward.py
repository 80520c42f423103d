"""The expected total reward until a target, minimised or maximised, in rational
arithmetic: Storm's ``R{"r"}min=? [F target]`` and ``R{"r"}max=? [F target]`` on an MDP
whose probabilities and rewards are given as rationals.

The semantics are Storm's: a scheduler that does not reach the target with probability 1
has the value infinity, so

* ``Rmin``: a state from which no scheduler reaches the target almost surely
  (``Pmax(F target) < 1``) has the value infinity; on the others only the choices whose
  successors all keep ``Pmax = 1`` are of use (any other one gives infinity);
* ``Rmax``: a state from which some scheduler misses the target with positive
  probability (``Pmin(F target) < 1``) has the value infinity; on the others every
  scheduler reaches the target almost surely.

Both sets come from the graph alone (:func:`almost_sure`), never from a number.

The finite values are found by policy iteration in rationals: the policy's chain is
solved exactly, strongly connected block by block, successors first (a single state is
one division; a cyclic block one python-flint ``fmpq_mat.solve``, at most
:data:`mitld_lp.defaults.EXACT_MAX_BLOCK` states, checked before it), and each state
switches to a choice that is strictly better by exact comparison, until none is.

Why the result is the optimum, exactly.  Start: for ``Rmin`` the attractor policy (each
state a choice that keeps ``Pmax = 1`` and moves closer to the target), for ``Rmax`` any
choice: both reach the target almost surely.  A strict switch never closes a cycle that
avoids the target (on such a cycle's stationary law the values would have to drop
strictly and stay equal), so every policy met reaches the target almost surely and its
values ``v`` are finite and the chain's system is non-singular.  At the end, ``Rmin``:
``v`` is a policy's value (``v >= Rmin``) and ``v(s) <= r(c) + P_c v`` for every useful
choice ``c``, a sub-solution of the Bellman operator with ``v = 0`` on the target; for
any scheduler reaching the target almost surely that gives ``v <= `` its expected reward
(unroll the inequality ``n`` steps; ``v`` is bounded and the chance of not being at the
target goes to 0), so ``v <= Rmin``.  ``Rmax``: ``v <= Rmax`` as a policy's value, and
``v(s) >= r(c) + P_c v`` for every choice with ``v >= 0`` makes ``v`` a pre-fixed point
above the least one, which ``Rmax`` is (rewards are non-negative).  Hence ``v`` is the
optimum itself: the bracket is the exact value rounded outward.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.exact.errors import ExactError, ExactTooLarge, TimeUp
from mitld_lp.solvers.graph import graph_blocks
from mitld_lp.solvers.reward_graph import almost_sure, attractor_policy, keeps_inside
from mitld_lp.worlds.prism_rewards import RewardMDP

__all__ = ["RewardAnswer", "solve_reward", "to_fraction"]


@dataclass(frozen=True, slots=True)
class RewardAnswer:
    """The optimum at the initial state: ``value`` (a :class:`Fraction`, or None for
    infinity), the states of value infinity (``infinite``, as the graph decides them),
    the policy (a choice per state, -1 where it does not matter), the policy evaluations
    it took and the states switched."""

    value: Fraction | None
    infinite: np.ndarray
    policy: np.ndarray
    rounds: int
    switched: int
    useful_choices: int


def to_fraction(q: Any) -> Fraction:
    """A python-flint ``fmpq`` (or any rational with ``p``/``q`` or numerator and
    denominator) as a :class:`Fraction`."""
    if isinstance(q, Fraction):
        return q
    if hasattr(q, "p") and hasattr(q, "q"):
        return Fraction(int(q.p), int(q.q))
    return Fraction(q)


class _Solver:
    def __init__(self, model: RewardMDP, finite: np.ndarray, useful: np.ndarray,
                 max_block: int, deadline: float) -> None:
        from flint import fmpq, fmpq_mat

        self.fmpq, self.fmpq_mat = fmpq, fmpq_mat
        self.model, self.useful, self.max_block, self.deadline = model, useful, max_block, deadline
        self.p = [fmpq(int(x.numerator), int(x.denominator)) if isinstance(x, Fraction)
                  else fmpq(x) for x in model.probabilities]
        self.r = [fmpq(int(x.numerator), int(x.denominator)) if isinstance(x, Fraction)
                  else fmpq(x) for x in model.rewards]
        self.indptr = model.indptr.tolist()
        self.indices = model.indices.tolist()
        self.solve = finite & ~model.target

    def _clock(self) -> None:
        if time.perf_counter() > self.deadline:
            raise TimeUp

    def value(self, c: int, v: list[Any]) -> Any:
        q = self.r[c]
        for k in range(self.indptr[c], self.indptr[c + 1]):
            q += self.p[k] * v[self.indices[k]]
        return q

    def evaluate(self, policy: np.ndarray) -> list[Any]:
        """The policy's exact expected rewards (0 on the target; 0 as a placeholder where
        the value is infinite: no useful choice leads there)."""
        n = self.model.n_states
        v = [self.fmpq(0)] * n
        idx = np.flatnonzero(self.solve)
        if not idx.size:
            return v
        local = np.full(n, -1, dtype=np.int64)
        local[idx] = np.arange(idx.size)
        rows = policy[idx]
        counts = self.model.indptr[rows + 1] - self.model.indptr[rows]
        src = np.repeat(np.arange(idx.size), counts)
        dst = local[np.concatenate([self.model.indices[self.model.indptr[c]:
                                                       self.model.indptr[c + 1]]
                                    for c in rows.tolist()])]
        inside = dst >= 0
        graph = sp.csr_array((np.ones(int(inside.sum()), dtype=bool),
                              (src[inside], dst[inside])), shape=(idx.size, idx.size))
        blocks = graph_blocks(graph, np.zeros(0))
        for level in blocks.walk():  # successors' blocks first
            self._clock()
            members = idx[level.states]
            comps = blocks.component[level.states]
            for comp in np.unique(comps).tolist():
                self._block(members[comps == comp].tolist(), policy, v)
        return v

    def _block(self, states: list[int], policy: np.ndarray, v: list[Any]) -> None:
        """The values of one strongly connected block ``B`` of the chain (its
        successors' known): ``(I - P_BB) x = r_B + P_B,out v``, exactly; one state is
        one division."""
        k = len(states)
        if k > self.max_block:
            raise ExactTooLarge(
                f"expected reward: the policy's chain has a cyclic block of {k:,} states, "
                f"more than the {self.max_block:,} an exact solve factorises "
                "(mitld_lp.defaults.EXACT_MAX_BLOCK)")
        position = dict(zip(states, range(k), strict=True))
        system = [[self.fmpq(0)] * k for _ in range(k)]
        known = []
        for row, s in enumerate(states):
            c = int(policy[s])
            system[row][row] += 1
            constant = self.r[c]
            for e in range(self.indptr[c], self.indptr[c + 1]):
                col = position.get(self.indices[e])
                if col is None:
                    constant += self.p[e] * v[self.indices[e]]
                else:
                    system[row][col] -= self.p[e]
            known.append(constant)
        if k == 1:
            if system[0][0] == 0:  # a policy reaching the target has no such state
                raise ArithmeticError(f"state {states[0]}: its policy choice loops forever")
            v[states[0]] = known[0] / system[0][0]
            return
        flat = [x for line in system for x in line]
        solution = self.fmpq_mat(k, k, flat).solve(self.fmpq_mat(k, 1, known))
        for row, s in enumerate(states):
            v[s] = solution[row, 0]

    def improve(self, policy: np.ndarray, v: list[Any], sense: str) -> int:
        """Each state switched to its best useful choice where that is strictly better
        than ``v``; the number of switches."""
        owner = self.model.owner
        best: dict[int, tuple[Any, int]] = {}  # state -> (best value so far, its choice)
        for c in np.flatnonzero(self.useful).tolist():
            self._clock()
            s = int(owner[c])
            q = self.value(c, v)
            held = best.get(s, (v[s], -1))[0]
            if (q > held) if sense == "max" else (q < held):
                best[s] = (q, c)
        moved = [(s, c) for s, (_, c) in best.items() if c != policy[s]]
        for s, c in moved:
            policy[s] = c
        return len(moved)


def solve_reward(model: RewardMDP, sense: str, *, time_limit: float | None = None,
                 max_block: int = defaults.EXACT_MAX_BLOCK) -> RewardAnswer:
    """``Rmin`` (``sense`` "min") or ``Rmax`` ("max") of the expected total reward until
    the target, exactly (module docs).  Raises :class:`ExactTooLarge` for a cyclic block
    past ``max_block``, :class:`TimeUp` past ``time_limit`` seconds."""
    if sense not in ("min", "max"):
        raise ValueError(f"sense must be 'min' or 'max', got {sense!r}")
    try:
        import flint  # noqa: F401
    except ImportError:
        raise ExactError("an expected reward is computed in rational arithmetic with "
                         "python-flint: pip install 'mitld_lp[exact]'") from None
    if any(to_fraction(r) < 0 for r in model.rewards):
        raise ValueError("expected reward: a negative reward (the rewards must be >= 0)")
    deadline = time.perf_counter() + (float("inf") if time_limit is None else time_limit)
    finite = almost_sure(model, sense)
    owner = model.owner
    useful = keeps_inside(model, finite) & finite[owner] & ~model.target[owner]
    if sense == "min":
        policy = attractor_policy(model, finite, useful)
    else:
        policy = np.full(model.n_states, -1, dtype=np.int64)
        first = np.unique(owner[useful], return_index=True)[1]
        policy[owner[np.flatnonzero(useful)[first]]] = np.flatnonzero(useful)[first]
    solver = _Solver(model, finite, useful, max_block, deadline)
    if (policy[solver.solve] < 0).any():  # the graph analysis guarantees a choice
        raise AssertionError("expected reward: a finite state without a useful choice")
    rounds = switched = 0
    while True:
        v = solver.evaluate(policy)
        rounds += 1
        moved = solver.improve(policy, v, sense)
        switched += moved
        if not moved:
            break
    initial = model.initial
    value = None if not finite[initial] else to_fraction(v[initial])
    return RewardAnswer(value=value, infinite=~finite, policy=policy, rounds=rounds,
                        switched=switched, useful_choices=int(useful.sum()))
