"""The controlled chain of a controller that acts on sensor reports where some event's
law is known only within a band: an interval model for Storm's robust check, and the
controller's worst case over the band read from it.

Its states are those of :mod:`mitld_lp.running.sensed_chain` (the truth: world state,
automaton state on the true events, pending events, clock, unreported sensed events;
the controller's memory: its information state, moved by its own tables), its labels
too.  At every step nature picks each pending band event's hazard inside the band at
the true clock (docs/robust.md, "What is solved": the adversary who has seen everything,
the robot's action included), the events then happen independently: the same semantics
as the robust route's interval MDP (:mod:`mitld_lp.product.imdp`).  The value of a step
is multilinear in the hazards, so nature's best reply is at a corner of the box of
hazards: each state has one choice per corner (named ``act/b1=lo``, ``act/b1=hi``), each
the exact distribution of the step at that corner, written as point intervals; the file
is an interval MDP whose every choice is nature's (the form
:mod:`mitld_lp.running.band_chain` writes for two band events at once).  Storm's
``Pmin=? [F "accept"]`` with the uncertainty resolved to the minimum is the
controller's worst case over the band; :func:`worst_case` computes it here by value
iteration from below (every iterate is the worst case of reaching ``accept`` within that
many steps, so a sound lower bound), less an allowance for the floats' rounding.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.running.band_chain import BAND_PROPERTY, BandChain, band_chain_drn
from mitld_lp.running.sensed_chain import sensed_corner_unfolding

__all__ = ["SensedBandValue", "is_sensed_band", "sensed_band_chain", "sensed_band_chain_of",
           "sensed_band_claim", "worst_case", "write_sensed_band_chain", "BAND_PROPERTY"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class SensedBandValue:
    """The controller's worst case over the band on its chain: ``lower`` a sound lower
    bound (the iterate less the rounding allowance), ``last_change`` the iteration's
    last change (how far from converged it stopped), ``iterations``, ``n_states``;
    ``truncated_won`` the same worst case with the runs past a truncation point counted
    as reaching ``accept`` (the upper truncation model's reading: how much of the gap to
    an upper bound is the truncation's, not the band's)."""

    lower: float
    last_change: float
    iterations: int
    n_states: int
    truncated_won: float = float("nan")


def is_sensed_band(result: Any) -> bool:
    """Whether ``result`` answers a problem with sensors that miss events and a band (its
    route's part says its lower end is a worst case over the band)."""
    return bool(getattr(getattr(result, "part", None), "band_worst", False))


def sensed_band_claim(result: Any) -> tuple[float, str]:
    """What Storm's check of the file gives against ``result``'s bracket: the bound and
    the sentence the command line prints."""
    how = f"{BAND_PROPERTY} with uncertainty MINIMIZE"
    if result.complemented:  # the complement's automaton: "accept" marks failing runs
        bound = result.complement[0] if result.complement is not None else 1 - result.upper
        return bound, (f"{how} >= the complement's lower = {bound!r}: for a minimised "
                       "task \"accept\" marks the runs that fail it (1 - it is upper, the "
                       "controller's worst case over the bands)")
    return result.lower, (f"{how} >= lower = {result.lower!r}, the controller's worst "
                          "case over the bands")


def sensed_band_chain(game: Any, dta: Any, sta: Any, sensors: Any, controller: Any,
                      max_states: int | None = None) -> BandChain:
    """The interval chain (module docs) of ``controller`` in ``game`` with the task's
    automaton ``dta``, the events' clocks ``sta`` (bands included) and the ``sensors``
    (at most ``max_states`` states, else :class:`~mitld_lp.util.memory.ProductTooLarge`)."""
    chain, choices = sensed_corner_unfolding(game, dta, sta, sensors, controller,
                                             max_states)
    rows = [row for here in choices for _, row in here]
    names = tuple(name for here in choices for name, _ in here)
    n = len(choices)
    indptr = np.zeros(len(rows) + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=indptr[1:])
    cols = np.fromiter((c for r in rows for c in sorted(r)), dtype=np.int64,
                       count=int(indptr[-1]))
    vals = np.fromiter((r[c] for r in rows for c in sorted(r)), dtype=np.float64,
                       count=int(indptr[-1]))
    matrix = sp.csr_array((vals, cols, indptr), shape=(len(rows), n))
    groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([len(h) for h in choices], out=groups[1:])
    return BandChain(matrix, vals.copy(), groups, names, chain.labels, chain.valuations,
                     chain.origin)


def sensed_band_chain_of(result: Any, controller: Any = None,
                         max_states: int | None = None) -> BandChain:
    """The interval chain of a sensed answer whose laws include a band, under its
    controller or ``controller`` (one of the same model), at most ``max_states``."""
    c = controller if controller is not None else result.controller
    if c is None:
        raise ValueError(f"no controller to export: the synthesis is {result.status}")
    return sensed_band_chain(result.model.game, result.dta, result.sta, result.sensors, c,
                             max_states)


def worst_case(chain: BandChain, *, tol: float = 1e-13, max_iterations: int = 1_000_000
               ) -> SensedBandValue:
    """``Pmin(F accept)`` of ``chain`` from its state 0, nature minimising over each
    state's choices: value iteration from below until no value changes by more than
    ``tol`` (module docs); and ``Pmin(F (accept | truncated))`` the same way."""
    accept = chain.accepting()
    truncated = np.array(["truncated" in x for x in chain.labels], dtype=bool)
    low, change, k = _from_below(chain, accept, tol, max_iterations)
    high = _from_below(chain, accept | truncated, tol, max_iterations)[0]
    return SensedBandValue(low, change, k, chain.n_states, high)


def _from_below(chain: BandChain, target: np.ndarray, tol: float, max_iterations: int
                ) -> tuple[float, float, int]:
    """Nature's least probability of reaching ``target`` from state 0, from below, less
    the floats' rounding allowance; the last change; the iterations."""
    m = chain.matrix
    starts = chain.row_groups[:-1]
    v = target.astype(np.float64)
    change, k = 1.0, 0
    while change > tol and k < max_iterations:
        nxt = np.minimum.reduceat(m @ v, starts) if m.shape[0] else v
        nxt[target] = 1.0
        change = float(np.max(nxt - v)) if v.size else 0.0
        v, k = nxt, k + 1
    allowance = 4.0 * np.finfo(np.float64).eps * (k + 1)
    return max(float(v[0]) - allowance, 0.0), change, k


def write_sensed_band_chain(result: Any, path: str | os.PathLike[str], *,
                            controller: Any = None, overwrite: bool = False) -> Path:
    """Write the interval chain of a sensed answer with a band
    (:func:`sensed_band_chain_of`) to ``path`` (``.drn``) under the package's rule for
    output files; Storm's ``Pmin=? [F "accept"]`` with uncertainty MINIMIZE reads it."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(band_chain_drn(sensed_band_chain_of(result, controller)), out,
                     overwrite=overwrite)
