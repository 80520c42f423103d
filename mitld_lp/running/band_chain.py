"""The controlled chain of a robust controller (a law known only within a band), as an
interval Markov chain for Storm's robust check.

Its states are those the controller reaches against some law of the bands: the world
state and the controller's memory (automaton state ``q``, pending events, clock), as
in :mod:`mitld_lp.running.chain`, built from the interval MDP the controller was
synthesised on; the controller's action is asked of the controller itself (its
tables, live or loaded from its file), never read from the synthesis's policy vector.
Where the action's step may bring events whose law is a band, nature picks their
hazards in the bands (docs/robust.md, "What is solved"):

* one such event: the step goes to two *outcome states* (the event came, or not) with
  the intervals ``[lo, hi]`` and ``[1 - hi, 1 - lo]``, each then moving by the exact
  row of its outcome: exactly the band's hazards;
* ``k >= 2`` at once: the state has one choice per corner of the box of hazards (named
  ``action/b1=lo/b2=hi``), each the exact distribution at that corner.  Storm's
  intervals cannot say this (they let the joint outcomes vary independently, a larger
  set than independent hazards), and nature's best reply is at a corner, so the corners
  are exactly its power; the file is then an interval MDP whose every choice is nature's.

Every other probability is written as the point interval ``[p, p]``.  Labels as in the
controlled chain: ``accept`` where the automaton has accepted, and for a task with a
safety part on the greatest set of states of persistent automaton states that no law of
the bands can leave; ``reject``, ``truncated`` and the world's propositions.  Storm's
``Pmin=? [F "accept"]`` with the uncertainty resolved to the minimum
(``uncertainty_resolution_mode=MINIMIZE``) is the controller's worst case over the
bands: inside the certified bracket, at least ``lower``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.files.drn import DrnModel
from mitld_lp.product import ProductState
from mitld_lp.product.imdp import IntervalMDP, vertex_weights
from mitld_lp.running.chain_model import prop_labels
from mitld_lp.running.chain_steps import choice_of, state_marks, stops
from mitld_lp.worlds.names import state_fields

__all__ = ["BandChain", "band_chain", "band_chain_of", "band_chain_drn", "band_claim",
           "is_band", "write_band_chain", "BAND_PROPERTY"]

BAND_PROPERTY = 'Pmin=? [F "accept"]'
"""The property Storm checks on the file, with ``uncertainty_resolution_mode=MINIMIZE``."""

_CAME = ("no", "yes")


@dataclass(frozen=True, slots=True, eq=False)
class BandChain:
    """An interval chain (module docstring): state 0 is the initial one.

    ``matrix``: ``(n_choices, n_states)`` CSR, the intervals' lower ends; ``upper``
    their upper ends, one per stored entry; ``row_groups``: the choices of each state
    (one, except where nature picks a corner); ``choice_names``; ``labels[i]``,
    ``valuations[i]``; ``origin[i]``: its product state (-1 for outcome states and the
    chain's own absorbing states)."""

    matrix: sp.csr_array
    upper: np.ndarray
    row_groups: np.ndarray
    choice_names: tuple[str, ...]
    labels: tuple[frozenset[str], ...]
    valuations: tuple[str, ...]
    origin: np.ndarray

    @property
    def n_states(self) -> int:
        return self.matrix.shape[1]

    def accepting(self) -> np.ndarray:
        return np.array(["accept" in x for x in self.labels], dtype=bool)


def is_band(result: Any) -> bool:
    """Whether ``result`` is a robust answer (the one place this module asks it: its
    route's part says its model is an interval MDP)."""
    part = getattr(result, "part", None)
    return bool(getattr(part, "interval", False))


def _answer(result: Any) -> tuple[IntervalMDP, Any, frozenset[int], Any]:
    """The robust answer's pieces the chain needs: its interval MDP, its world, the
    automaton states in which staying for ever is acceptance, its controller."""
    if not is_band(result) or not isinstance(result.mdp, IntervalMDP):
        raise ValueError("not a robust answer (a law known only within a band)")
    return result.mdp, result.model.game, frozenset(result.dta.persistent), result.controller


def band_chain_of(result: Any, controller: Any = None) -> BandChain:
    """The interval chain of a robust ``result`` under its controller, or under
    ``controller`` (one of the same model, such as the result's saved and loaded)."""
    imdp, game, persistent, own = _answer(result)
    c = own if controller is None else controller
    if c is None:
        raise ValueError(f"no controller to export: the synthesis is {result.status}")
    return band_chain(imdp, c, persistent, game)


def band_chain(imdp: IntervalMDP, controller: Any, persistent: frozenset[int],
               game: Any) -> BandChain:
    """The interval chain (module docstring) of a deterministic ``controller`` on
    ``imdp``, the interval product of ``game`` with the controller's automaton."""
    if getattr(controller, "randomised", False):
        raise ValueError("the interval chain is written for a deterministic controller")
    plan: Any = controller.plan
    props = prop_labels()
    fields = (*state_fields(game), "q", "pending", "clock")
    index: dict[Any, int] = {}
    order: list[Any] = []
    rows: list[list[tuple[str, dict[int, tuple[float, float]]]]] = []  # per state: choices

    def number(node: Any) -> int:
        at = index.get(node)
        if at is None:
            at = index[node] = len(order)
            order.append(node)
        return at

    def exact(row: int) -> dict[int, tuple[float, float]]:
        lo, hi = int(imdp.branches.indptr[row]), int(imdp.branches.indptr[row + 1])
        return {number(("p", int(j))): (float(p), float(p)) for j, p in zip(
            imdp.branches.indices[lo:hi].tolist(), imdp.branches.data[lo:hi].tolist(),
            strict=True) if p > 0}

    number(("p", int(imdp.initial)))
    while len(rows) < len(order):
        node, here = order[len(rows)], len(rows)
        if node[0] == "end":
            rows.append([("absorb", {here: (1.0, 1.0)})])
        elif node[0] == "out":  # an outcome state: the exact row of its branch
            rows.append([("world", exact(node[1]))])
        else:
            rows.append(_steps(imdp, plan, node[1], here, number, exact))
    return _record(imdp, game, plan, persistent, order, rows, props, fields)


def _steps(imdp: IntervalMDP, plan: Any, i: int, here: int, number: Any,
           exact: Any) -> list[tuple[str, dict[int, tuple[float, float]]]]:
    """The choices of product state ``i`` (module docstring)."""
    rec = imdp.states[i]
    if not isinstance(rec, ProductState):  # target, sink, truncated: absorbing
        return [("absorb", {here: (1.0, 1.0)})]
    stop = stops(plan, rec)
    if stop is None:
        d = plan.decide(rec.game, rec.automaton, rec.pending, rec.clock)
        stop = "reject" if d.lost else None
    if stop is not None:
        return [("stop", {number(("end", stop)): (1.0, 1.0)})]
    action = d.actions[0] if d.actions else plan.fallback(rec.game)
    c = choice_of(imdp, i, action)
    first = int(imdp.branch_groups[c])
    bands = slice(int(imdp.band_groups[c]), int(imdp.band_groups[c + 1]))
    lo, hi = imdp.band_lo[bands], imdp.band_hi[bands]
    events = imdp.band_events[bands]
    if lo.size == 0:
        return [(action, exact(first))]
    if lo.size == 1:
        went = {number(("out", first + b, i, action, events[0], b)): span for b, span in
                ((0, (1.0 - float(hi[0]), 1.0 - float(lo[0]))),
                 (1, (float(lo[0]), float(hi[0])))) if span[1] > 0}
        return [(action, went)]
    w = vertex_weights(lo[None, :], hi[None, :])[0]  # (corner, branch)
    rows = sp.csr_array(w) @ imdp.branches[first:first + w.shape[1]]
    out = []
    for v in range(w.shape[0]):
        name = "/".join([action, *(f"{e}={'hi' if v >> k & 1 else 'lo'}"
                                   for k, e in enumerate(events))])
        r = rows[[v]]
        out.append((name, {number(("p", int(j))): (float(p), float(p)) for j, p in zip(
            r.indices.tolist(), r.data.tolist(), strict=True) if p > 0}))
    return out


def _record(imdp: IntervalMDP, game: Any, plan: Any, persistent: frozenset[int],
            order: list[Any], rows: list[Any], props: Any,
            fields: tuple[str, ...]) -> BandChain:
    n = len(order)
    groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum([len(r) for r in rows], out=groups[1:])
    flat = [succ for r in rows for _, succ in r]
    indptr = np.zeros(len(flat) + 1, dtype=np.int64)
    np.cumsum([len(s) for s in flat], out=indptr[1:])
    cols = np.array([j for s in flat for j in sorted(s)], dtype=np.int64)
    lo = np.array([s[j][0] for s in flat for j in sorted(s)], dtype=np.float64)
    hi = np.array([s[j][1] for s in flat for j in sorted(s)], dtype=np.float64)
    matrix = sp.csr_array((lo, cols, indptr), shape=(len(flat), n))
    labels: list[set[str]] = []
    valuations: list[str] = []
    origin = np.full(n, -1, dtype=np.int64)
    keep = np.zeros(n, dtype=bool)  # may belong to the set kept for ever
    for k, node in enumerate(order):
        if node[0] == "end":
            labels.append({node[1]})
            valuations.append(node[1])
        elif node[0] == "out":
            _, _, i, action, event, came = node
            labels.append(set())
            parent = state_marks(game, plan.verdicts, imdp.states[i], props, fields)[1]
            valuations.append(f"{parent} & "
                              f"action={action} & {event}={_CAME[came]}")
            keep[k] = True
        else:
            origin[k] = node[1]
            rec = imdp.states[node[1]]
            marks, text = state_marks(game, plan.verdicts, rec, props, fields)
            labels.append(marks)
            valuations.append(text)
            keep[k] = isinstance(rec, ProductState) and rec.automaton in persistent
    if persistent:
        for k in np.flatnonzero(_closed(matrix, hi, groups, keep) & (origin >= 0)).tolist():
            labels[k].add("accept")
    names = tuple(name for r in rows for name, _ in r)
    return BandChain(matrix, hi, groups, names, tuple(frozenset(x) for x in labels),
                     tuple(valuations), origin)


def _closed(matrix: sp.csr_array, hi: np.ndarray, groups: np.ndarray,
            inside: np.ndarray) -> np.ndarray:
    """The greatest subset of ``inside`` that no choice leaves with positive probability
    (an entry whose upper end is positive): from there every law of the bands keeps the
    run in it for ever."""
    owner = np.repeat(np.repeat(np.arange(groups.size - 1), np.diff(groups)),
                      np.diff(matrix.indptr))
    moves = hi > 0
    src, dst = owner[moves], matrix.indices[moves]
    inside = inside.copy()
    while True:
        leaving = np.unique(src[inside[src] & ~inside[dst]])
        if leaving.size == 0:
            return inside
        inside[leaving] = False


def band_chain_drn(chain: BandChain) -> DrnModel:
    """The chain as Storm's explicit DRN with intervals, for the one DRN writer
    (:mod:`mitld_lp.files.drn`): ``@type: DTMC`` when nature's only choices are
    intervals, ``MDP`` when it picks corners; ``accept`` declared even when no state
    carries it (the value is then 0)."""
    n = chain.n_states
    names = sorted(set().union(*chain.labels))
    labels = tuple((name, np.fromiter((name in x for x in chain.labels), dtype=bool,
                                      count=n)) for name in names)
    actions = tuple(sorted(set(chain.choice_names)))
    at = {a: k for k, a in enumerate(actions)}
    one = bool(np.all(np.diff(chain.row_groups) == 1))
    return DrnModel(matrix=chain.matrix, row_groups=chain.row_groups, initial=0,
                    kind="DTMC" if one else "MDP", labels=labels, declared=("accept",),
                    action_names=actions,
                    choice_actions=np.array([at[a] for a in chain.choice_names],
                                            dtype=np.int64),
                    upper=chain.upper, valuations=chain.valuations,
                    comment="The controlled interval chain of a robust controller, "
                    "exported by mitld_lp")


def band_claim(result: Any) -> tuple[float, str]:
    """What Storm's check of the file gives, against ``result``'s bracket: the bound and
    the sentence the command line prints."""
    how = f"{BAND_PROPERTY} with uncertainty MINIMIZE"
    if result.complemented:  # the complement's automaton: "accept" marks failing runs
        bound = result.complement[0] if result.complement is not None else 1 - result.upper
        return bound, (f"{how} >= the complement's lower = {bound!r}: for a minimised "
                       "task \"accept\" marks the runs that fail it")
    return result.lower, f"{how} >= lower = {result.lower!r}, the worst case over the bands"


def write_band_chain(result: Any, path: str | os.PathLike[str], *, controller: Any = None,
                     overwrite: bool = False) -> Path:
    """Write the interval chain of robust ``result`` (:func:`band_chain_of`) to ``path``
    (``.drn``) under the package's rule for output files."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(band_chain_drn(band_chain_of(result, controller)), out,
                     overwrite=overwrite)
