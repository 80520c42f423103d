"""Sensors whose reports come too late for the task (issue 41): a delay past the step from
which the task no longer depends on when the sensed events happened gives the blind
sensor's answer, and is built as the blind sensor before any state is; the bound is
derived by hand here for each task, the collapsed answer compared with the blind one,
with the answer built in full at the smallest delay past the bound, and with the
exhaustive expectimax of test_sensing.py."""

from __future__ import annotations

import math
import tracemalloc
from pathlib import Path

import pytest
from test_sensing import PMF, SPEC, STATION, WINDOW, expectimax_many

from mitld_lp import Model, loads_model, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic.parser import parse
from mitld_lp.product import ProductTooLarge
from mitld_lp.sensing import belief as belief_module
from mitld_lp.sensing.horizon import Collapse, forgetting_horizon
from mitld_lp.sensing.observe import simulate_sensed
from mitld_lp.sensing.saved import load_sensed

BUS = (Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml").read_text()


def _bus(sensor: str) -> Model:
    return loads_model(BUS.replace("[distributions]", f"[sensors]\nb1 = {sensor}\n\n"
                                                       "[distributions]"))


def _in_full(monkeypatch) -> None:
    """From now on, build every sensor as given (no collapse), to compare with the
    collapsed build."""
    monkeypatch.setattr(belief_module, "collapse",
                        lambda dta, sensors, points: Collapse(0, None, frozenset(), sensors))


# By hand, for two hypotheses "b at k1" < "b at k2" read on the same letters: the pair is
# done once one is decided or both are equal; L counts the steps after k2.
@pytest.mark.parametrize(("spec", "sensed", "by_hand"), [
    # b at k1's window [k1, k1+2] ends at k1 + 2 <= k2 + 1: it is decided by then
    ("D[mu] b & F(b & F[0,2] A)", ["b"], 1),
    # windows [k+2, k+5]: k1's ends at k1 + 5 <= k2 + 4
    ("D[mu] b & F(b & F[2,5] A)", ["b"], 4),
    # a failed b1 window leaves the b2 part open: equal only when k2's window ends too
    ("(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))", ["b1"], 3),
    # once b came, "F A" is pending in both (or one has accepted): equal at once
    ("D[mu] b & F(b & F A)", ["b"], 0),
    # an A between k1 and k2 leaves k1 at "F B", k2 at "F(A & F B)" while neither comes
    ("D[mu] b & F(b & F(A & F B))", ["b"], None),
])
def test_the_forgetting_horizon_by_hand(spec, sensed, by_hand):
    assert forgetting_horizon(to_dta(parse(spec)), sensed) == by_hand


@pytest.mark.parametrize("delay", [100_000, 10**12])
def test_the_bus_case_with_a_huge_delay_is_the_blind_case(delay, monkeypatch):
    # issue 41: b1 = { detect = 0.5, delay = 100000 } passed 4.3 GB in 90 s; b1 comes by
    # step T = 3 (geometric(0.8): P(K > 3) = 0.2^3 = 0.008 <= epsilon 0.01, P(K > 2) =
    # 0.04 is not) and the task forgets when after L = 3 steps (above): every delay >= T +
    # L - 1 = 5 is blind.  Within 10 MB here, where the build in full ran out
    late = synthesize(_bus(f"{{ detect = 0.5, delay = {delay} }}"), max_memory=10 << 20)
    blind = synthesize(_bus("{ detect = 0 }"))
    short = synthesize(_bus("{ detect = 0.5, delay = 4 }"))  # one step short of the bound
    _in_full(monkeypatch)
    past = synthesize(_bus("{ detect = 0.5, delay = 5 }"))  # the smallest past it, in full
    assert late.certified and late.sta.truncation_points == {"b1": 3}
    for other in (blind, past):
        assert other.certified
        assert late.lower == pytest.approx(other.lower, abs=1e-9)
        assert late.upper == pytest.approx(other.upper, abs=1e-9)
    assert late.mdp.n_states == blind.mdp.n_states < past.mdp.n_states
    # the bound is tight here: a report at step 5 can still save the b1 window [3, 6]
    assert short.lower - blind.lower > 1e-7
    assert late.summary()["sensors"] == {"b1": 0.5}  # the sensor as given


def test_a_late_sensor_equals_the_exhaustive_expectimax(monkeypatch):
    # STATION: the bus comes at step 1..4 (T = 4), the window F[0,2] forgets after
    # L = 1 step: every delay >= 4 is blind.  The expectimax knows none of this
    horizon = len(PMF) + WINDOW
    blind = expectimax_many(STATION, [(PMF, 0.0, "A", WINDOW)], horizon=horizon)
    at_bound = expectimax_many(STATION, [(PMF, 0.7, "A", WINDOW, 4)], horizon=horizon)
    late = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.7,
                                                                     "delay": 10**6}}))
    assert late.certified and late.lower - 1e-9 <= blind <= late.upper + 1e-9
    _in_full(monkeypatch)
    full = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.7,
                                                                     "delay": 4}}))
    assert full.lower - 1e-9 <= at_bound <= full.upper + 1e-9
    assert abs(late.lower - full.lower) < 1e-9


def test_the_collapsed_controller_ignores_the_late_reports(tmp_path):
    # a perfect sensor four steps late (at the bound) reports within the runs: the
    # controller built as blind must take those reports as nothing new, never as an
    # observation beyond its model; saved and loaded, it does the same
    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 1.0, "delay": 4}})
    r = synthesize(model)
    assert r.controller.ignored == {"b"}
    sim = simulate_sensed(model, r.controller, runs=3000, seed=4)
    assert sim.beyond_model == 0
    assert abs(sim.estimate - r.lower) <= 4.5 * math.sqrt(r.lower * (1 - r.lower) / 3000)
    loaded = load_sensed(r.controller.save(tmp_path / "c.npz"))
    assert loaded.ignored == {"b"}
    assert simulate_sensed(model, loaded, runs=300, seed=9) == simulate_sensed(
        model, r.controller, runs=300, seed=9)


def test_a_delay_the_task_uses_for_ever_is_stopped_by_the_memory_budget():
    # F(b & F(A & F B)): which of A, B came after b matters until one comes, so a report
    # never comes too late and nothing collapses; the clock is kept up to T + delay, and
    # the budget stops the build before the memory it names is spent
    model = loads_model(
        'name = "u"\nspec = "D[pmf(0.5, 0.5)] b & F(b & F(A & F B))"\n[grid]\n'
        "size = [3, 1]\nstart = [1, 0]\nslip = 0.2\n[regions]\nA = [[0, 0]]\n"
        "B = [[2, 0]]\n[sensors]\nb = { detect = 0.5, delay = 1000000 }\n")
    tracemalloc.start()
    try:
        with pytest.raises(ProductTooLarge, match=r"more than 4,194,304 bytes .*the clock "
                                                  r"kept up to step 1,000,002"):
            synthesize(model, max_memory=4 << 20)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2 * (4 << 20)
