"""The interval chain of a sensed controller under a band
(:mod:`mitld_lp.running.sensed_corners`: each state's step unfolded once and shared by
nature's corners) against the construction it replaced, written here: every corner's
step made from scratch by the one-corner-at-a-time chain's own step
(:class:`~mitld_lp.running.sensed_chain.Unfolding` with the corner's hazards), the
valuations from the whole state's fields at once.  The two must give the same chain to
the bit: the same states in the same order, the same choices, every probability's
bits, labels, valuations, origins and reward models.  Small answers of the sensed band
routes: a deterministic controller, randomised ones with a constraint (several actions
drawn, nature's corner per action), with false alarms, a safety task's keeps, and a
band whose laws may never happen.  And the reachability of
:func:`~mitld_lp.running.sensed_band_chain._live` against one search per seed."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
import test_false_alarms_band_constrained as fa
from test_sensing_tasks import STATION

from mitld_lp import Model, synthesize
from mitld_lp.controllers.format import UNDECIDED
from mitld_lp.controllers.tables import BEYOND
from mitld_lp.distributions import from_table, pmf
from mitld_lp.distributions.band import band_of_laws
from mitld_lp.running import sensed_band_chain
from mitld_lp.running.sensed_chain import TaskEnds, Unfolding, plan_of
from mitld_lp.sensing import Sensor
from mitld_lp.worlds.names import state_fields, state_values, valuation_text


class _Reference(Unfolding):
    """Every corner's step made from scratch (the construction before the template)."""

    def corners(self) -> tuple[Any, list[list[tuple[str, dict[int, float]]]]]:
        self.start()
        choices: list[list[tuple[str, dict[int, float]]]] = []
        while len(choices) < len(self.order):
            node = self.order[len(choices)]
            if isinstance(node, str):
                choices.append([("stay", {len(choices): 1.0})])
                continue
            clock = node[3]
            bands = {a: self.sta.clocks[a].band(clock) for a in sorted(node[2])}
            open_ = [a for a, (lo, hi) in bands.items() if lo < hi]
            drawn = self.drawn(node) if open_ else [None]
            here = []
            boxes = list(itertools.product((0, 1), repeat=len(open_)))
            for pick in itertools.product(boxes, repeat=len(drawn)):
                self.per_action = {act: {a: bands[a][e] for a, e in zip(open_, ends, strict=True)}
                                   for act, ends in zip(drawn, pick, strict=True)}
                name = "/".join(["act"] + [
                    ("" if act is None else f"{act}:") + f"{a}={'hi' if e else 'lo'}"
                    for act, ends in zip(drawn, pick, strict=True)
                    for a, e in zip(open_, ends, strict=True)])
                here.append((name, self.step(node)))
            choices.append(here)
        # each successor's greatest probability over the corners, in order of first sight
        union = [{k: max(r.get(k, 0.0) for _, r in here)
                  for k in dict.fromkeys(k for _, r in here for k in r)} for here in choices]
        return self.record(union), choices

    def drawn(self, node: tuple[Any, ...]) -> list[Any]:
        g, memory = node[0], node[5]
        if UNDECIDED not in self.plan.verdicts_at(memory):
            return [None]
        d = self.plan.decision(g, memory)
        if d.lost or d.weights is None or not d.actions:
            return [None]
        acts = [a for a, x in zip(d.actions, d.weights, strict=True) if x > 0.0]
        return acts if len(acts) > 1 else [None]

    def moves(self, node: Any, action: str, p_action: float, row: dict[int, float]) -> None:
        self.corner = self.per_action.get(action, self.per_action.get(None, {}))
        super().moves(node, action, p_action, row)

    def events(self, pending: frozenset[str], clock: int) -> list[tuple[frozenset[str], float]]:
        out: list[tuple[frozenset[str], float]] = [(frozenset(), 1.0)]
        for a in sorted(pending):
            h = self.corner.get(a, self.sta.clocks[a].band(clock)[0])
            out = [(e | {a}, p * h) for e, p in out] + [(e, p * (1.0 - h)) for e, p in out]
        return [(e, p) for e, p in out if p > 0.0]


def _old_valuation(u: Unfolding, node: Any) -> str:
    """A state's valuation from all its fields at once."""
    if isinstance(node, str):
        return node
    g, q, pending, clock, unreported, memory = node
    waiting = ",".join(f"{a}:{w}" for a, w in zip(u.sensed, unreported, strict=True) if w != -1)
    fields = (*state_fields(u.game), "q", "pending", "clock", "unreported", "memory")
    return valuation_text(fields, (*state_values(u.game, g), q,
                                   "{" + ",".join(sorted(pending)) + "}", clock,
                                   "{" + waiting + "}",
                                   "beyond" if memory == BEYOND else str(memory)))


def _reference(made: list[_Reference]) -> Any:
    def unfold(game: Any, dta: Any, sta: Any, sensors: Any, controller: Any,
               max_states: int | None = None, *, ends: Any = None) -> Any:
        plan, sensed = plan_of(controller, sensors)
        u = _Reference(game, dta, sta, sensors, sensed, plan, ends or TaskEnds(dta))
        made.append(u)
        return u.corners()
    return unfold


def _same(a: Any, b: Any) -> None:
    (ca, ra), (cb, rb) = a, b
    for x, y in ((ca.matrix.data, cb.matrix.data), (ca.upper, cb.upper)):
        assert x.tobytes() == y.tobytes()  # every probability's bits
    for x, y in ((ca.matrix.indices, cb.matrix.indices), (ca.matrix.indptr, cb.matrix.indptr),
                 (ca.row_groups, cb.row_groups), (ca.origin, cb.origin)):
        assert np.array_equal(x, y)
    assert ca.choice_names == cb.choice_names
    assert ca.labels == cb.labels and ca.valuations == cb.valuations
    assert [n for n, _ in ra] == [n for n, _ in rb]
    for (_, x), (_, y) in zip(ra, rb, strict=True):
        assert x.tobytes() == y.tobytes()


def _station(spec: str, **kw: Any) -> Model:
    law = from_table({"geometric": [0.3, 0.5]}, "mu")
    return Model.from_game(STATION, spec, events={"b": law},
                           sensors={"b": {"detect": 0.5}}, epsilon=0.3, **kw)


def _never() -> Model:
    band = band_of_laws("mu", pmf([0.3, 0.3]), [pmf([0.2, 0.3]), pmf([0.4, 0.3])])
    return Model.from_game(fa.GAME, fa.SPEC, distributions={"mu": band},
                           sensors={"b": Sensor(0.6)})


CASES = {
    "deterministic": (lambda: fa.model(alarm="0"), {}),
    "constraint": (lambda: fa.model(alarm="0", game=fa.WAITING),
                   {"constraints": [fa.CONSTRAINT]}),
    "false alarms, then": (lambda: fa.model(), {"constraints": [fa.CONSTRAINT],
                                                "then": "min-steps"}),
    "safety keeps": (lambda: _station("G !(b & A)"), {"then": "min-steps"}),
    "may never happen": (_never, {"constraints": [fa.CONSTRAINT]}),
}


@pytest.fixture(scope="module")
def answers() -> dict[str, Any]:
    return {name: synthesize(make(), **kw) for name, (make, kw) in CASES.items()}


@pytest.mark.parametrize("name", list(CASES))
def test_the_chain_is_the_one_every_corner_made_alone_gives(
        name: str, answers: dict[str, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    r = answers[name]
    assert r.controller is not None and sensed_band_chain.is_sensed_band(r), r.status
    new = sensed_band_chain.sensed_band_unfolding_of(r)
    made: list[_Reference] = []
    monkeypatch.setattr(sensed_band_chain, "sensed_corner_unfolding", _reference(made))
    old = sensed_band_chain.sensed_band_unfolding_of(r)
    _same(new, old)
    (u,) = made
    assert list(new[0].valuations) == [_old_valuation(u, x) for x in u.order]
    chain = new[0]
    nature = np.diff(chain.row_groups)
    assert chain.n_states > 3 and nature.max() >= 2  # a band open somewhere
    if name in ("constraint", "false alarms, then", "safety keeps"):
        assert nature.max() >= 4  # a corner per action drawn
    if name == "may never happen":  # its event leaves "pending" at the truncation point
        assert all(c.keeps_never and c.truncation for c in r.sta.clocks.values())
    if name == "safety keeps":  # its controller keeps the task somewhere
        from mitld_lp.running.sensed_joint import keeps_for

        assert keeps_for(r.belief, r.joint).states.any()


def test_the_worst_case_read_from_the_chain_is_the_answer_s(answers: dict[str, Any]) -> None:
    """The deterministic controller's worst case on its chain is its answer's lower."""
    r = answers["deterministic"]
    got = sensed_band_chain.worst_case(sensed_band_chain.sensed_band_chain_of(r))
    assert abs(got.lower - r.lower) <= 1e-9


def _live_by_seed(rows: sp.csr_array, seeds: np.ndarray) -> np.ndarray:
    from scipy.sparse.csgraph import breadth_first_order

    back = sp.csr_array(rows.T)
    live = np.zeros(rows.shape[0], dtype=bool)
    for s0 in np.flatnonzero(seeds).tolist():
        live[breadth_first_order(back, s0, return_predecessors=False)] = True
    return live


@pytest.mark.parametrize("seed", range(6))
def test_the_states_reaching_the_seeds_are_those_one_search_a_seed_finds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    dense = (rng.random((n, n)) < 2.0 / n) * rng.random((n, n))
    dense[rng.random((n, n)) < 0.05] = 0.0
    rows = sp.csr_array(dense)
    for density in (0.0, 0.1, 0.5):
        seeds = rng.random(n) < density
        got = sensed_band_chain._live(rows, seeds)
        assert np.array_equal(got, _live_by_seed(rows, seeds))
        assert not got.any() if not seeds.any() else got[seeds].all()
