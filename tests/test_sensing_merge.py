"""The merge of information states whose futures are identical
(:mod:`mitld_lp.sensing.merge`): a sensed event's times shifted to a canonical place
where only their differences matter.

* the claim, in exact arithmetic and independently of the package: over every
  observation history of a small case, written here from the semantics (a geometric
  bus, a camera that misses, no hazards tables, no automaton, no information states),
  two histories whose hypotheses are the same up to the shift have the same exact
  posterior (so the same future: the same conditional law of everything that follows);
  under a law whose hazard changes they do not (the check has teeth), and the package
  does not shift there;
* the package's merged product is the quotient of its unmerged one by that shift: every
  state of the one is a state of the other shifted, with the same posterior, and every
  row lumps onto the merged row (probabilities to 1e-12);
* the same optimum with and without the merge, inside the exhaustive expectimax's
  bracket, on one and on two sensed events."""

from __future__ import annotations

import dataclasses
import functools
from collections import defaultdict
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType

import pytest
from test_sensing import STATION, expectimax

from mitld_lp import Model, load_model, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import Sensor
from mitld_lp.sensing import belief as belief_module
from mitld_lp.sensing.belief import InfoState, belief_product
from mitld_lp.sensing.merge import shift_start
from mitld_lp.sensing.rules import StepRules

MODELS = Path(__file__).resolve().parents[1] / "models"
P, D = Fraction(2, 5), Fraction(3, 5)  # the bus's hazard, the camera's detection
SPEC = "D[geometric(0.4)] b & F(b & F[0,2] A)"  # at A at step k, k + 1 or k + 2


# ------------------------------------------------------------------ exact, by hand

def histories(horizon: int, hazard=lambda t: P):
    """Every observation history of STATION with the bus coming at step ``t + 1`` with
    probability ``hazard(t)`` if not before (by default geometric(2/5)) and the camera
    (detect 3/5) up to ``horizon`` steps, under every action: ``(t, world, reported,
    masses)``, ``masses`` the unnormalised probability of each hypothesis still open
    (``("not yet", None)`` or ``(k, steps of its window left)``: the bus came at step
    ``k``, the robot has not been at A since), the world's own factors left out (the
    same for every hypothesis of one history)."""
    out = []

    def walk(t, world, reported, masses):
        out.append((t, world, reported, masses))
        if t == horizon:
            return
        for action in STATION.actions(world):
            for nxt, _ in STATION.successors(world, action, frozenset()):
                for seen in (False, True):
                    step = defaultdict(Fraction)
                    for (k, left), m in masses.items():
                        if k == "not yet":  # the bus comes now (reported or not) or not
                            h = hazard(t)
                            if not seen:
                                step[("not yet", None)] += m * (1 - h)
                            branches = [(t + 1, 3, m * h * (D if seen else 1 - D))]
                        elif reported:  # reported before: no report can come again
                            branches = [] if seen else [(k, left, m)]
                        else:
                            branches = [(k, left, m * (D if seen else 1 - D))]
                        for k2, left2, m2 in branches:
                            left2 -= 1  # this step of the window used
                            if m2 and "A" not in STATION.propositions(nxt) and left2 > 0:
                                step[(k2, left2)] += m2  # still open (caught: decided)
                    step = {h: m for h, m in step.items() if m}
                    if step:
                        walk(t + 1, nxt, reported or seen, step)

    walk(0, STATION.initial, False, {("not yet", None): Fraction(1)})
    return out


def posterior(masses):
    total = sum(masses.values())
    return {h: m / total for h, m in masses.items()}


def canonical(t, world, reported, masses):
    """The history's key with the bus's times shifted so that the earliest is step 1,
    when every open hypothesis has the bus come; the step count is kept while "not
    yet" is open (its hazard's clock)."""
    times = [k for k, _ in masses if k != "not yet"]
    open_ = any(k == "not yet" for k, _ in masses)
    shift = min(times) - 1 if times and not open_ else 0
    moved = {((k, left) if k == "not yet" else (k - shift, left)): m
             for (k, left), m in masses.items()}
    return (t if open_ else None, world, reported, frozenset(moved)), moved


def _grouped(hazard=lambda t: P):
    seen: dict = defaultdict(list)
    for t, world, reported, masses in histories(6, hazard):
        key, moved = canonical(t, world, reported, masses)
        seen[key].append((frozenset(masses), posterior(moved)))
    return seen


def test_histories_equal_up_to_the_shift_have_the_same_exact_posterior():
    merged = 0
    for group in _grouped().values():
        first = group[0][1]
        assert all(post == first for _, post in group)
        merged += len({hyps for hyps, _ in group}) > 1  # different times, one state
    assert merged > 0  # the shift does merge histories whose bus times differ


def test_the_shift_is_wrong_where_the_hazard_changes_and_is_not_made():
    # pmf(0.1, 0.2, 0.3, 0.4): hazards 1/10, 2/9, 3/7, 1 at steps 1..4, so P(K = k) /
    # P(K = k + 1) is not one ratio: shifted histories disagree (the check has teeth) ...
    hazards = (Fraction(1, 10), Fraction(2, 9), Fraction(3, 7), Fraction(1))
    grouped = _grouped(lambda t: hazards[t] if t < 4 else Fraction(0))
    assert any(any(post != group[0][1] for _, post in group) for group in grouped.values())
    # ... and the package shifts only from the step where the hazards stay equal: 4,
    # the last (no bus comes later than 4, so no state has a least time above it)
    model = Model.from_game(STATION, "D[pmf(0.1, 0.2, 0.3, 0.4)] b & F(b & F[0,2] A)",
                            sensors={"b": {"detect": 0.6}})
    sensors = dict(model.sensors)
    sta = belief_module.sensed_sta(to_dta(model.spec), model.distributions, ("b",),
                                   model.epsilon, sensors=sensors)
    assert shift_start(sta, "b") == 4
    station = _station_model()
    geometric = belief_module.sensed_sta(to_dta(station.spec), station.distributions,
                                         ("b",), 1e-3, sensors=sensors)
    assert shift_start(geometric, "b") == 1


# ------------------------------------------------------------------ the package

def _station_model() -> Model:
    return Model.from_game(STATION, SPEC, sensors={"b": {"detect": float(D)}},
                           epsilon=1e-3)


def _products():
    model = _station_model()
    dta = to_dta(model.spec)
    built = {merge: belief_product(model.game, dta, model.distributions,
                                   dict(model.sensors), model.epsilon, max_states=10**6,
                                   merge=merge)
             for merge in (False, True)}
    return model, dta, built


def _rows(mdp, i):
    """The rows of state ``i``: action name to {successor: probability}."""
    out = {}
    for c in range(mdp.row_groups[i], mdp.row_groups[i + 1]):
        row = mdp.matrix[[c], :]
        act = int(mdp.choice_actions[c])
        name = mdp.action_names[act] if act >= 0 else None
        out[name] = dict(zip(row.indices.tolist(), row.data.tolist(), strict=True))
    return out


def test_the_merged_product_is_the_unmerged_one_shifted():
    model, dta, built = _products()
    plain, merged = built[False], built[True]
    rules = StepRules(model.game, dta, plain.sta, plain.sensed, dict(model.sensors))

    def key(s):
        """The test's shift of one unmerged state (module docs of merge.py, written out
        for one event reported at once: geometric hazards are equal from step 1)."""
        if not isinstance(s, InfoState):
            return s
        ks = [times[0] for times, _ in s.hypotheses]
        if min(ks) <= 1:  # "not yet" (0) open, or already canonical
            return s.key()
        hyps = tuple(((k - min(ks) + 1,), q) for k, (_, q) in zip(ks, s.hypotheses,
                                                                  strict=True))
        clock = rules.clock_key(s.clock, [h for h, _ in hyps], s.pending, s.reported)
        return (s.world, clock, s.reported, s.pending, hyps)

    states = {key(s): i for i, s in enumerate(merged.mdp.states)}
    assert len(states) == merged.mdp.n_states < plain.mdp.n_states  # merging applied
    assert {key(s) for s in plain.mdp.states} == set(states)
    for i, s in enumerate(plain.mdp.states):
        j = states[key(s)]
        if isinstance(s, InfoState):
            assert merged.mdp.states[j].weights == pytest.approx(s.weights, abs=1e-12)
        lumped = {}
        for act, row in _rows(plain.mdp, i).items():
            summed: dict = defaultdict(float)
            for col, p in row.items():
                summed[states[key(plain.mdp.states[col])]] += p
            lumped[act] = summed
        mine = _rows(merged.mdp, j)
        assert set(mine) == set(lumped)
        for act, row in mine.items():
            assert set(row) == set(lumped[act])
            assert all(abs(row[c] - lumped[act][c]) <= 1e-12 for c in row)


def _solve(model: Model, merge: bool, monkeypatch):
    monkeypatch.setattr(belief_module, "belief_product",
                        functools.partial(belief_product, merge=merge))
    return synthesize(model)


def test_the_same_optimum_with_and_without_the_merge(monkeypatch):
    model = _station_model()
    merged, plain = (_solve(model, m, monkeypatch) for m in (True, False))
    assert merged.mdp.n_states < plain.mdp.n_states
    assert merged.certified and plain.certified
    assert abs(merged.lower - plain.lower) <= 1e-12
    assert abs(merged.upper - plain.upper) <= 1e-12
    # the exhaustive expectimax with the buses after step 8 lost (low) or caught
    # (low + 0.6^8), over a horizon that judges every bus up to 8 (test_sensing's)
    pmf = tuple(0.4 * 0.6 ** (k - 1) for k in range(1, 9))
    low = expectimax(STATION, pmf, float(D), 2, "A", horizon=10)
    assert merged.lower - 1e-7 <= low + 0.6 ** 8 and low - 1e-7 <= merged.upper


def test_two_cameras_the_same_optimum_with_and_without_the_merge(monkeypatch):
    base = load_model(MODELS / "bus_grid.toml")
    model = dataclasses.replace(base, epsilon=0.05, sensors=MappingProxyType(
        {"b1": Sensor(0.7), "b2": Sensor(0.7)}))
    merged, plain = (_solve(model, m, monkeypatch) for m in (True, False))
    assert merged.mdp.n_states < plain.mdp.n_states
    assert merged.certified and plain.certified
    assert abs(merged.lower - plain.lower) <= 1e-12
    assert abs(merged.upper - plain.upper) <= 1e-12
