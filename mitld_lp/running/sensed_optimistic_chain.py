"""The best case over a band of a controller that acts on sensor reports (``bands =
"best"`` with a sensor that misses), and its controlled chain at nature's chosen law.

The controller's interval chain (:mod:`mitld_lp.running.sensed_band_chain`: the truth
and the controller's memory, one choice per corner of the box of the pending band
events' hazards, each the exact distribution of the step at that corner) has nature's
choices only.  Read optimistically, nature picks the corners that help the robot most,
seeing everything, as in the worst case it picks those that hurt it: the controller's
best case over the band is ``Pmax(F accept)`` of that chain.

:func:`best_case` finds it by value iteration from below, then fixes nature's half: at
each state one corner among those within a tie of the best against the values, and
among them one by which the state enters the attractor of ``accept`` (so that no loop
the values alone would allow keeps the run from it); every other state keeps its first
corner.  That fixes a law of the band (a hazard at an end of the band for each pending
event at every step, chosen on the run so far), and the chain at it is a plain Markov
chain (:func:`law_chain`); ``lower`` is that chain's probability of ``accept`` by value
iteration from below (every iterate is the probability within that many steps), less
an allowance for the floats' rounding: a sound lower bound of the controller's best
case.  ``export --chain`` writes that chain, on which Storm's ``P=? [F "accept"]`` is
at least ``lower`` (:func:`mitld_lp.running.optimistic_chain.optimistic_claim` says so,
as for the fully observed optimistic answer); the answer claims nothing about other
laws.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.running.band_chain import BandChain
from mitld_lp.running.chain_model import Chain
from mitld_lp.running.sensed_band_chain import (
    reach_from_below,
    reach_min,
    sensed_band_chain_of,
)

__all__ = ["BestCase", "best_case", "law_chain", "is_sensed_optimistic",
           "sensed_optimistic_chain_of"]


@dataclass(frozen=True, slots=True, eq=False)
class BestCase:
    """A controller's best case over the band on its interval chain: ``lower`` the
    chain at nature's chosen corners (``rows``, one choice row of the interval chain per
    state) reaching ``accept``, a sound lower bound; ``best`` the value iteration's
    ``Pmax(F accept)`` over every choice of nature (also from below: ``lower`` is at most
    it up to the rounding allowance and the iteration's stop); ``last_change`` and
    ``iterations`` of that iteration; ``truncated_won`` the best case with the runs past
    a truncation point counted as reaching ``accept`` (from below: how much of the gap to
    an upper bound is the truncation's)."""

    lower: float
    best: float
    last_change: float
    iterations: int
    n_states: int
    rows: np.ndarray
    truncated_won: float = float("nan")


def best_case(chain: BandChain, *, tol: float = 1e-13, max_iterations: int = 1_000_000
              ) -> BestCase:
    """Nature's best corners for ``accept`` on ``chain`` and the chain's value at them
    (module docs)."""
    accept = chain.accepting()
    truncated = np.array(["truncated" in x for x in chain.labels], dtype=bool)
    v, change, k = reach_from_below(chain, accept, tol, max_iterations, maximise=True)
    rows = _attracting_rows(chain, accept, v)
    lower = reach_min(_fixed(chain, rows), accept, tol=tol, max_iterations=max_iterations)
    won = reach_from_below(chain, accept | truncated, tol, max_iterations,
                           maximise=True)[0]
    return BestCase(lower, _floor(float(v[0]), k), change, k, chain.n_states, rows,
                    _floor(float(won[0]), k))


def law_chain(chain: BandChain, rows: np.ndarray) -> Chain:
    """The plain chain of ``chain`` with nature's choice ``rows[i]`` (a row of
    ``chain.matrix``) at each state ``i``: labels, valuations and product states kept."""
    plain = sp.csr_array(chain.matrix[np.asarray(rows, dtype=np.int64)])
    plain.eliminate_zeros()
    plain.sort_indices()
    n = chain.n_states
    return Chain(plain, chain.labels, chain.valuations, chain.origin,
                 np.zeros(n, dtype=bool), np.zeros(n, dtype=bool))


def is_sensed_optimistic(result: Any) -> bool:
    """Whether ``result`` answers a problem with sensors that miss events and a band read
    for its best law (its route's part says so)."""
    return bool(getattr(getattr(result, "part", None), "band_best", False))


def sensed_optimistic_chain_of(result: Any, controller: Any = None,
                               max_states: int | None = None) -> Chain:
    """The controlled chain at nature's chosen law (module docs) of such an answer's
    controller, or of ``controller`` (one of the same model: its own best corners are
    found on its own interval chain), at most ``max_states`` states."""
    if not is_sensed_optimistic(result):
        raise ValueError("not an answer with sensors and the bands read for their best law")
    part = result.part
    if controller is None and part.chain is not None:
        return law_chain(part.chain, part.best.rows)
    chain = sensed_band_chain_of(result, controller, max_states)
    return law_chain(chain, best_case(chain).rows)


def _attracting_rows(chain: BandChain, target: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Per state, a choice row within a tie of the best against ``v`` by which the state
    enters the attractor of ``target`` over such rows (layer by layer from ``target``);
    the state's first row where none does (its value is 0, or the iteration stopped
    short)."""
    m, groups, n = chain.matrix, chain.row_groups, chain.n_states
    owner = np.repeat(np.arange(n), np.diff(groups))
    q = m @ v
    best = np.maximum.reduceat(q, groups[:-1]) if m.shape[0] else v
    tied = q >= best[owner] - 1e-12 * (1.0 + np.abs(best[owner]))
    rows = groups[:-1].astype(np.int64).copy()
    done = np.asarray(target, dtype=bool).copy()
    while True:
        enters = (m @ done.astype(np.float64)) > 0.0
        ok = np.flatnonzero(tied & enters & ~done[owner])
        if ok.size == 0:
            return rows
        states, first = np.unique(owner[ok], return_index=True)
        rows[states] = ok[first]
        done[states] = True


def _fixed(chain: BandChain, rows: np.ndarray) -> BandChain:
    """``chain`` with nature's choice fixed to ``rows`` (one choice a state)."""
    n = chain.n_states
    sub = sp.csr_array(chain.matrix[rows])
    return BandChain(sub, sub.data.copy(), np.arange(n + 1, dtype=np.int64),
                     tuple(chain.choice_names[i] for i in rows.tolist()), chain.labels,
                     chain.valuations, chain.origin)


def _floor(value: float, iterations: int) -> float:
    """``value`` less the floats' rounding allowance of ``iterations`` steps (each a
    matrix product of probabilities), at least 0."""
    return max(value - 4.0 * float(np.finfo(np.float64).eps) * (iterations + 1), 0.0)
