"""The controlled chain: the Markov chain of the world under a controller, for anyone to
re-check with Storm (``P=? [F "accept"]``) or PRISM.

The chain's states are the states the controller can reach: the world state, the
controller's memory (the automaton state, the events still pending, the clock) and, for
a randomised controller, whether it has drawn *stay* (it then keeps to an end component
for ever) or *keep* (it then plays an end component of persistent task states for ever,
which keeps the task's safety part). They are built from the product the controller was
synthesised on, so a step moves the world, lets the events happen with their hazards and
advances the clock exactly as there; the controller's choice is asked of the controller
itself (its tables, the same ones ``act`` reads), not read from the synthesis's arrays.
Runs past a truncation point go to the one state labelled ``truncated``, counted as
failure, as ``lower`` counts them.

Labels: ``init``; ``accept`` on the states from which the controller's run is accepted
for sure -- where the automaton has accepted, and, for a task with a safety part, on
every bottom strongly connected component of the chain whose automaton states are all
persistent (a run that enters it stays in it and keeps the safety part for ever), and,
for a randomised controller of a task with a safety part, on every state reached after
drawing *keep* (labelled ``keeping`` too); so ``P=? [F "accept"]`` is the probability
that the run is accepted: the controller's value, inside the synthesis's certified
bracket, ``lower`` its bound from below (for a minimum solved as one, on the task's own
automaton, ``P=? [F ("accept" | "truncated")]`` is bounded from above by ``upper``; for a
minimised task read back from its complement, ``P=? [F "accept"]`` from below by the
complement's lower bound, ``result.complement[0]``). ``reject`` where the
task is lost (the controller stops), ``truncated`` as above, ``staying`` where a
randomised controller keeps to an end component, and each world proposition that holds
(a proposition named like one of these labels is written ``world_<name>``). Each state
line is followed by its valuation as a comment, as Storm's own exporter writes it:
``//[x=1 & y=2 & q=3 & pending={b1} & clock=0]``.
"""

from __future__ import annotations

import os
from collections.abc import Hashable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.controllers.kinds import ControllerLike
from mitld_lp.files import drn
from mitld_lp.files import write as files
from mitld_lp.files.drn import DrnModel
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState
from mitld_lp.running.chain_model import CHAIN_LABELS, Chain, prop_labels, rows_matrix
from mitld_lp.running.chain_steps import choice_of, state_marks, stops
from mitld_lp.util.traversal import strong_components
from mitld_lp.worlds.game import Game
from mitld_lp.worlds.names import state_fields

__all__ = ["Chain", "controlled_chain", "chain_of", "write_chain", "CHAIN_LABELS",
           "prop_labels", "rows_matrix", "choice_of", "stops", "state_marks"]

_GO, _STAY, _KEEP = 0, 1, 2
"""A randomised controller's mode, part of a chain state: acting by its distribution,
staying in an end component for ever, keeping the task's safety part for ever."""


def chain_of(result: Any, controller: ControllerLike | None = None) -> Chain:
    """The controlled chain of a synthesis result (:class:`~mitld_lp.SynthesisResult`
    or a constrained result) under its controller (or ``controller``, one built on the
    same product).  A robust result (a law within a band) is refused: its controller
    runs on an interval model, whose controlled system is no Markov chain (its interval
    chain: :func:`mitld_lp.running.band_chain.band_chain_of`).  A result
    with sensors that miss events has the chain of :mod:`mitld_lp.running.sensed_chain`
    (the truth and what the robot has observed)."""
    from mitld_lp.running.sensed_chain import is_sensed, sensed_chain_of

    if is_sensed(result):
        if getattr(result.part, "band_best", False):  # at nature's chosen law of the band
            from mitld_lp.running.sensed_optimistic_chain import sensed_optimistic_chain_of

            return sensed_optimistic_chain_of(result, controller)
        if getattr(result.part, "band_worst", False):
            raise ValueError("sensors with a law known only within a band: the controller's "
                             "controlled system is no Markov chain (nature picks each step's "
                             "hazard in the band); mitld_lp.running.sensed_band_chain."
                             "sensed_band_chain_of gives its interval chain (export --chain "
                             "writes it)")
        return sensed_chain_of(result, controller)
    if result.part.randomised:  # a constrained result: the joint automaton's product
        if result.controller is None and controller is None:
            raise ValueError(f"no controller to export: the synthesis is {result.status}")
        persistent: frozenset[int] = frozenset()  # joint acceptance is by reaching
        return controlled_chain(result.mdp, controller or result.controller,
                                persistent, world_of(result, controller))
    if result.lower_model is None or not isinstance(result.mdp, MDP):
        raise ValueError("a robust result (a law known only within a band): its "
                         "controller acts on an interval model, whose controlled system is "
                         "no Markov chain; mitld_lp.running.band_chain.band_chain_of gives "
                         "its interval chain (export --chain writes it)")
    return controlled_chain(result.mdp, controller or result.controller,
                            result.dta.persistent, result.model.game)


def world_of(result: Any, controller: ControllerLike | None = None) -> Game[Any]:
    """The world of a result: its model's, else the one its controller (or
    ``controller``) knows."""
    model = getattr(result, "model", None)
    if model is not None:
        return model.game
    for c in (result.controller, controller):
        try:
            return c.game  # type: ignore[union-attr]
        except AttributeError:
            continue
    raise ValueError("the result has no controller that knows its world")


def controlled_chain(mdp: MDP, controller: ControllerLike, persistent: Iterable[int],
                     game: Game[Any]) -> Chain:
    """The chain of ``controller`` on ``mdp``, the product of ``game`` with the
    controller's automaton (module docstring); ``persistent``: the automaton states in
    which staying for ever is acceptance."""
    keep = frozenset(persistent)
    fields = (*state_fields(game), "q", "pending", "clock")
    index: dict[tuple[int, int], int] = {}
    order: list[tuple[int, int]] = []
    rows: list[dict[int, float]] = []
    special: dict[str, int] = {}

    def number(node: tuple[int, int]) -> int:
        at = index.get(node)
        if at is None:
            at = index[node] = len(order)
            order.append(node)
        return at

    def sink(name: str) -> int:  # the chain's own absorbing state for a stopped run
        if name not in special:
            special[name] = number((-1 - len(special), _GO))
        return special[name]

    number((int(mdp.initial), _GO))
    done = 0
    while done < len(order):
        i, mode = order[done]
        row: dict[int, float] = {}
        if i < 0:
            row[done] = 1.0
        else:
            for j, mode_next, p in _moves(mdp, controller, i, mode, sink):
                if p > 0:
                    to = j if mode_next is None else number((j, mode_next))
                    row[to] = row.get(to, 0.0) + p
        rows.append(row)
        done += 1
    names = {v: k for k, v in special.items()}
    origin = np.array([i for i, _ in order], dtype=np.int64)
    modes = np.array([s for _, s in order], dtype=np.int64)
    matrix = rows_matrix(rows)
    props = prop_labels()
    labels: list[set[str]] = []
    valuations: list[str] = []
    plan_verdicts = controller.plan.verdicts  # type: ignore[attr-defined]
    for k, (i, mode) in enumerate(order):
        here: set[str] = set()
        if i < 0:
            here.add(names[k])
            valuations.append(names[k])
        else:
            marks, text = state_marks(game, plan_verdicts, mdp.states[i], props, fields)
            here |= marks
            valuations.append(text + _MODE_TEXT[mode])
            if mode == _STAY:
                here.add("staying")
            elif mode == _KEEP:  # the safety part kept for ever: the task accepted
                here |= {"keeping", "accept"}
        labels.append(here)
    for k in _kept_for_ever(matrix, order, mdp, keep):
        labels[k].add("accept")
    return Chain(matrix, tuple(frozenset(x) for x in labels), tuple(valuations), origin,
                 modes == _STAY, modes == _KEEP)



_MODE_TEXT = {_GO: "", _STAY: " & staying=true", _KEEP: " & keeping=true"}


def _moves(mdp: MDP, controller: ControllerLike, i: int, mode: int,
           sink: Any) -> Iterable[tuple[int, int | None, float]]:
    """The chain's steps from product state ``i`` in controller ``mode``: ``(j, mode,
    p)`` to product state ``j``, or ``(k, None, p)`` to the chain's own state ``k``
    (the draws of :meth:`mitld_lp.controllers.stepper.Stepper._act`, as probabilities)."""
    rec = mdp.states[i]
    if not isinstance(rec, ProductState):  # target, sink, truncated: absorbing
        yield i, _GO, 1.0
        return
    plan: Any = controller.plan  # the tables act() reads
    stop = stops(plan, rec)
    if stop is not None:  # every component decided: the controller stops
        yield sink(stop), None, 1.0
        return
    d = plan.decide(rec.game, rec.automaton, rec.pending, rec.clock)
    if d.lost:
        yield sink("reject"), None, 1.0
        return
    fallback = plan.fallback(rec.game)

    def uniform(actions: tuple[str, ...], p: float, after: int) -> list[tuple[str, float, int]]:
        if not actions:
            return [(fallback, p, after)]
        return [(a, p / len(actions), after) for a in actions]

    choice: list[tuple[str, float, int]] = []  # action, probability, mode after
    if d.weights is None or not d.actions:
        choice.append((d.actions[0] if d.actions else fallback, 1.0, mode))
    elif mode == _KEEP:
        choice += uniform(d.kept, 1.0, _KEEP)
    else:
        go_on = 0.0 if mode == _STAY else 1.0 - d.stay
        now_stay = 1.0 - go_on
        if now_stay > 0:
            choice += uniform(d.inside, now_stay, _STAY)
        total = float(np.sum(d.weights))
        if go_on > 0 and total > 0:
            for k, (a, w) in enumerate(zip(d.actions, d.weights, strict=True)):
                if w <= 0:
                    continue
                p = go_on * float(w) / total
                if d.keep and d.keep[k]:
                    choice += uniform(d.kept, p, _KEEP)
                else:
                    choice.append((a, p, _GO))
    matrix = mdp.matrix
    for action, p, after in choice:
        c = choice_of(mdp, i, action)
        lo, hi = int(matrix.indptr[c]), int(matrix.indptr[c + 1])
        for j, q in zip(matrix.indices[lo:hi].tolist(), matrix.data[lo:hi].tolist(),
                        strict=True):
            yield j, after, p * q




def _kept_for_ever(matrix: sp.csr_array, order: list[tuple[int, int]], mdp: MDP,
                   persistent: frozenset[int]) -> list[int]:
    """The states of the bottom strongly connected components whose every state is an
    ordinary product state with a persistent automaton state (and not *staying*, whose
    run decides nothing more)."""
    if not persistent:
        return []
    n = matrix.shape[0]
    count, comp = strong_components(matrix)
    coo = matrix.tocoo()
    leaves = np.zeros(count, dtype=bool)
    cross = (comp[coo.row] != comp[coo.col]) & (coo.data > 0)
    leaves[comp[coo.row[cross]]] = True
    good = np.ones(count, dtype=bool)
    for k in range(n):
        i, mode = order[k]
        rec = mdp.states[i] if i >= 0 else None
        if mode == _STAY or not isinstance(rec, ProductState) or rec.automaton not in persistent:
            good[comp[k]] = False
    return np.flatnonzero(good[comp] & ~leaves[comp]).tolist()


def chain_drn(chain: Chain) -> DrnModel:
    """The chain as Storm's explicit DRN (``@type: DTMC``), for the one DRN writer
    (:mod:`mitld_lp.files.drn`): each state's labels, in name order, and its valuation;
    ``accept`` declared even when no reachable state accepts (the value is 0)."""
    names = sorted(set().union(*chain.labels))
    labels = tuple((name, np.fromiter((name in x for x in chain.labels), dtype=bool,
                                      count=chain.n_states)) for name in names)
    return DrnModel(matrix=chain.matrix, row_groups=np.arange(chain.n_states + 1),
                    initial=0, kind="DTMC", labels=labels, declared=("accept",),
                    valuations=chain.valuations,
                    rewards=tuple(drn.Reward(name, r) for name, r in chain.rewards),
                    comment="The controlled chain, exported by mitld_lp")


def write_chain(result: Any, path: str | os.PathLike[str], *,
                controller: ControllerLike | None = None, overwrite: bool = False) -> Path:
    """Write the controlled chain of ``result`` (:func:`chain_of`) to ``path`` (``.drn``)
    under the package's rule for output files."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=drn.SUFFIXES)
    return drn.write(chain_drn(chain_of(result, controller)), out, overwrite=overwrite)


def reachable_states(chain: Chain) -> Iterable[Hashable]:
    """The product states the chain visits (for tests and reports)."""
    return sorted({int(i) for i in chain.origin if i >= 0})
