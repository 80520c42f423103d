"""The frontier-at-a-time construction of the information-state product
(:mod:`mitld_lp.sensing.frontier`) against a straightforward one written here: one state
at a time, dictionaries of tuples, the observations grouped by hand, from the step rules
of :mod:`mitld_lp.sensing.rules` (the rules are checked against an exhaustive
expectimax in test_sensing.py and test_sensing_tasks.py; what is checked here is the
bookkeeping: which states exist, their posteriors, every transition and every move).
Built without the merge of :mod:`mitld_lp.sensing.merge` (the reference keeps every
hypothesis's times as they came; tests/test_sensing_merge.py checks the merge).
Equal after canonical ordering: the same states (by key), the same choices, the same
successors with the same probabilities and the same posteriors (to the last bit: both
sum in the loops' order, with math.fsum where one state at a time uses it), the same
controller moves, and the states numbered in the same order."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Hashable
from pathlib import Path
from types import MappingProxyType
from typing import Any

import pytest
from test_sensing_tasks import PUSHED, STATION

from mitld_lp import Model, load_model
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import pmf
from mitld_lp.product import Absorbing, ProductTooLarge
from mitld_lp.sensing import Sensor
from mitld_lp.sensing.belief import Belief, InfoState, belief_product
from mitld_lp.sensing.rules import StepRules

MODELS = Path(__file__).resolve().parents[1] / "models"


def reference(model: Any, belief: Belief, dta: Any = None, ends: Any = None
              ) -> dict[str, Any]:
    """The product of ``model`` built one state at a time from ``belief``'s clocks and
    sensors (the ones the construction used), in canonical form: ``rows[(key, action)]``
    a dict of successor keys to probabilities, ``weights[key]``, ``moves[(key,
    action)]`` (successor keys or records), the initial key and the keys in the order
    a breadth-first build meets them (per state and action, the absorbing records as the
    loops meet them, then the new information states as their observations come).
    ``dta``, ``ends``: the automaton and where a hypothesis ends, if not the task's."""
    sensors = {a: s for a, s in model.sensors.items()}
    rules = StepRules(model.game, to_dta(model.spec) if dta is None else dta, belief.sta,
                      belief.sensed, sensors, ends)
    dta, game = rules.dta, model.game
    q0 = dta.step(dta.initial, frozenset(game.propositions(game.initial)))

    def state(world: Hashable, t: int, reported: frozenset[str], pending: frozenset[str],
              mass: dict[tuple[tuple[int, ...], int], float]) -> InfoState:
        hyps = tuple(sorted(mass))
        total = math.fsum(mass.values())
        return InfoState(world, rules.clock_key(t, [h for h, _ in hyps], pending, reported),
                         reported, pending, hyps, tuple(mass[h] / total for h in hyps))

    def key(s: InfoState | Hashable) -> Hashable:
        return s.key() if isinstance(s, InfoState) else s

    end0 = rules.end(q0, frozenset(belief.sta.events)) if ends is not None or q0 in (
        dta.accepting, dta.rejecting) else None
    start = end0 if end0 is not None else state(
        game.initial, 0, frozenset(), rules.unsensed,
        {((0,) * len(belief.sensed), q0): 1.0})
    rows: dict[tuple[Hashable, str], dict[Hashable, float]] = {}
    moves: dict[tuple[Hashable, str], dict[Any, Hashable]] = {}
    weights: dict[Hashable, tuple[float, ...]] = {}
    order = [start]  # numbered as first met, breadth first
    seen = {key(start)}
    head = 0
    while head < len(order):
        s = order[head]
        head += 1
        if not isinstance(s, InfoState):
            rows[(s, "loop")] = {s: 1.0}
            continue
        weights[key(s)] = s.weights
        for act in game.actions(s.world):
            row: dict[Hashable, float] = {}
            groups: dict[Any, dict[Any, float]] = {}
            ended: dict[Any, set[Hashable]] = {}
            found: list[InfoState | Hashable] = []
            for occurred, pu, crossed in rules.unsensed_outcomes(s.pending, s.clock):
                if crossed:
                    row[Absorbing.TRUNCATED] = row.get(Absorbing.TRUNCATED, 0.0) + pu
                    found.append(Absorbing.TRUNCATED)
                    continue
                for (times, q), w in zip(s.hypotheses, s.weights, strict=True):
                    for times2, new, pc, cut, now, waiting in rules.sensed_branches(
                            times, s.reported, s.clock):
                        if cut:
                            row[Absorbing.TRUNCATED] = row.get(Absorbing.TRUNCATED, 0.0) \
                                + w * pu * pc
                            found.append(Absorbing.TRUNCATED)
                            continue
                        for g2, pg in game.successors(s.world, act, occurred):
                            if pg <= 0.0:
                                continue
                            q2 = rules.automaton(q, rules.label(g2) | occurred | now)
                            end = rules.end(q2, (s.pending - occurred) | waiting)
                            obs = (g2, occurred, new)
                            if end is not None:
                                row[end] = row.get(end, 0.0) + w * pu * pc * pg
                                ended.setdefault(obs, set()).add(end)
                                found.append(end)
                            else:
                                g = groups.setdefault(obs, {})
                                g[(times2, q2)] = g.get((times2, q2), 0.0) + w * pu * pc * pg
            table: dict[Any, Hashable] = {}
            for obs, mass in groups.items():
                g2, occurred, new = obs
                s2 = state(g2, s.clock + 1, s.reported | new, s.pending - occurred, mass)
                row[key(s2)] = row.get(key(s2), 0.0) + math.fsum(mass.values())
                table[obs] = key(s2)
                found.append(s2)
            for obs, ends in ended.items():
                if obs not in table:
                    table[obs] = next(iter(ends)) if len(ends) == 1 else Absorbing.TRUNCATED
            rows[(key(s), act)] = row
            moves[(key(s), act)] = table
            for s2 in found:
                if key(s2) not in seen:
                    seen.add(key(s2))
                    order.append(s2)
    return {"rows": rows, "weights": weights, "moves": moves, "initial": key(start),
            "order": [key(s) for s in order]}


def canonical(belief: Belief) -> dict[str, Any]:
    """The built product in :func:`reference`'s form."""
    mdp = belief.mdp
    keys = [s.key() if isinstance(s, InfoState) else s for s in mdp.states]
    m = mdp.matrix.tocsr()
    rows = {}
    for i in range(mdp.n_states):
        for r in range(int(mdp.row_groups[i]), int(mdp.row_groups[i + 1])):
            a = int(mdp.choice_actions[r])
            act = "loop" if a < 0 else mdp.action_names[a]
            lo, hi = m.indptr[r], m.indptr[r + 1]
            row: dict[Hashable, float] = {}
            for j, p in zip(m.indices[lo:hi].tolist(), m.data[lo:hi].tolist(), strict=True):
                row[keys[j]] = row.get(keys[j], 0.0) + p
            assert (keys[i], act) not in rows  # one choice per action
            rows[(keys[i], act)] = row
    weights = {keys[i]: s.weights for i, s in enumerate(mdp.states)
               if isinstance(s, InfoState)}
    moves = {(keys[i], act): {obs: keys[j] if isinstance(j, int) else j
                              for obs, j in table.items()}
             for (i, act), table in belief.moves.items()}
    return {"rows": rows, "weights": weights, "moves": moves,
            "initial": keys[mdp.initial], "order": keys}


def with_sensors(name: str, sensors: dict[str, Sensor], epsilon: float) -> Model:
    base = load_model(MODELS / name)
    return dataclasses.replace(base, epsilon=epsilon, sensors=MappingProxyType(sensors))


CASES = {
    "one camera": lambda: with_sensors("bus_grid.toml", {"b1": Sensor(0.5)}, 0.05),
    "two cameras": lambda: with_sensors("bus_grid.toml", {"b1": Sensor(0.7),
                                                          "b2": Sensor(0.6)}, 0.3),
    "a delay": lambda: with_sensors("bus_grid.toml", {"b1": Sensor(0.5, delay=1)}, 0.05),
    "a safety part": lambda: with_sensors("bus_puddle.toml", {"b1": Sensor(0.5)}, 0.1),
    "may never come": lambda: Model.from_game(
        STATION, "D[pmf(0.3, 0.3)] b & F(b & F[0,2] A)", sensors={"b": {"detect": 0.5}},
        epsilon=1e-3),
    "safety, may never come": lambda: Model.from_game(
        PUSHED, "G !(b & A)", events={"b": pmf([0.3, 0.3])}, sensors={"b": {"detect": 0.8}},
        epsilon=1e-3),
}


def assert_same(belief: Belief, want: dict[str, Any]) -> None:
    got = canonical(belief)
    assert belief.mdp.n_states == len(want["order"])
    assert got["initial"] == want["initial"]
    # the same floats: summed in the same order (math.fsum where one state at a time
    # uses it), so equal to the last bit
    assert got["rows"] == want["rows"]
    assert got["weights"] == want["weights"]
    assert got["moves"] == want["moves"]
    # numbered as one state at a time numbers them: the solvers' ties break alike
    assert got["order"] == want["order"]


@pytest.mark.parametrize("case", sorted(CASES))
def test_frontier_build_equals_one_state_at_a_time(case: str) -> None:
    model = CASES[case]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6,
                            late_reports=False, merge=False)
    assert_same(belief, reference(model, belief))


def test_joint_automaton_ends_equal_one_state_at_a_time() -> None:
    """The constrained route's product: hypotheses of the joint automaton end in a
    verdict record per component (``ends``)."""
    from test_sensing import SPEC2, TWO

    from mitld_lp.routes.sensed_constrained import JointEnds
    from mitld_lp.routes.stages import joint_sta
    from mitld_lp.synthesis import pose

    model = Model.from_game(TWO, SPEC2, sensors={"b1": {"detect": 0.5},
                                                  "b2": {"detect": 0.7}})
    joint, sta = joint_sta(pose(model, ["P(F A) <= 0.2", "P(F B) >= 0.7"]))
    laws = {a: c.distribution for a, c in sta.clocks.items()}
    belief = belief_product(model.game, joint.dta, laws, dict(model.sensors),
                            model.epsilon, max_states=10**6, late_reports=False,
                            ends=JointEnds(joint), merge=False)
    assert_same(belief, reference(model, belief, joint.dta, JointEnds(joint)))


def test_moves_answer_as_a_mapping() -> None:
    """The moves are kept as arrays: a missing key is a KeyError (``get`` gives the
    default), every information state's action is a key, an absorbing state has none."""
    model = CASES["one camera"]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6)
    mdp = belief.mdp
    info = [i for i, s in enumerate(mdp.states) if isinstance(s, InfoState)]
    keys = list(belief.moves)
    assert len(keys) == len(belief.moves) == sum(
        len(model.game.actions(mdp.states[i].world)) for i in info)
    assert {i for i, _ in keys} == set(info)
    absorbing = next(i for i, s in enumerate(mdp.states) if not isinstance(s, InfoState))
    assert belief.moves.get((absorbing, "right")) is None
    assert (info[0], "no such action") not in belief.moves
    with pytest.raises(KeyError):
        belief.moves[(len(mdp.states) + 5, "right")]


def test_state_budget_stops_the_build() -> None:
    model = CASES["two cameras"]()
    with pytest.raises(ProductTooLarge, match="more than 100 states"):
        belief_product(model.game, to_dta(model.spec), model.distributions,
                       dict(model.sensors), model.epsilon, max_states=100)


def test_sums_per_group_are_math_fsum() -> None:
    """The groups' totals are correctly rounded (as math.fsum) on sums where the plain
    left-to-right sum is not: terms of many magnitudes, halves, thirds."""
    import numpy as np

    from mitld_lp.sensing.rows import fsum_by

    rng = np.random.default_rng(7)
    plain_differs = 0
    for trial in range(60):
        counts = rng.integers(1, 12, 300)
        ids = np.repeat(np.arange(300), counts)
        v = rng.random(len(ids)) * 10.0 ** rng.integers(-20, 1, len(ids))
        if trial % 2:
            v = 0.5 ** rng.integers(0, 60, len(ids)) * rng.choice([0.3, 0.7, 1 / 3], len(ids))
        starts = np.cumsum(counts) - counts
        want = [math.fsum(v[a:a + k].tolist()) for a, k in zip(starts, counts, strict=True)]
        assert fsum_by(ids, v, 300).tolist() == want
        plain_differs += int((np.bincount(ids, weights=v) != np.array(want)).sum())
    assert plain_differs > 100  # the case is not trivial
