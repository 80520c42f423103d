"""Constraints and ``then`` with a sensor that gives false alarms (the ``sensed-constrained``
route on the information states that keep each hypothesis's count of reports before its
report was due, tests/test_false_alarms.py's construction) against an occupancy LP
written here from the semantics and solved by scipy's linprog: the robot's knowledge
after ``t`` steps is its world state, its sensor's report or silence at *every* step so
far and the steps it stood at the stop; the bus's steps are weighed by the likelihood of
that report history (``false_alarm`` before the bus, ``detect`` from it on) -- no
automaton, no counts, no information-state builder of the package.  Storm re-checks the
exported chain of the randomised controller."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from storm_exact import exact_fraction
from test_false_alarms import LAW, TASKS
from test_sensed_constrained import (
    HORIZON,
    PMF,
    SPEC,
    STATION,
    WET_LATER,
    WINDOW,
    best,
    knowledge_lp,
)

from mitld_lp import Model, synthesize
from mitld_lp.distributions import pmf

DETECT, FALSE_ALARM = 0.5, 0.2


def _model(false_alarm: float = FALSE_ALARM) -> Model:
    return Model.from_game(STATION, SPEC, sensors={"b": {"detect": DETECT,
                                                         "false_alarm": false_alarm}})


def _likelihood(k: int, history: tuple[bool, ...], detect: float, fa: float,
                law: tuple[float, ...] = PMF) -> float:
    """The probability of the report history (one entry per step from step 1) under the
    bus at step ``k`` (of ``law``): a report w.p. ``fa`` before step ``k``, ``detect``
    from it on."""
    out = law[k - 1]
    for j, seen in enumerate(history, start=1):
        q = detect if j >= k else fa
        out *= q if seen else 1.0 - q
    return out


def every_step_lp(detect: float, fa: float, law: tuple[float, ...] = PMF) -> dict[str, Any]:
    """The occupancy LP over the knowledge ``(t, world, reports of steps 1..t, steps at
    the stop)`` (variables per knowledge and action for ``t < HORIZON``), as
    tests/test_sensed_constrained.py's ``knowledge_lp`` with the whole report history in
    place of the first report's step; sparse (up to 2^HORIZON histories a path).
    ``law``: the bus's step's masses (a mass after ``HORIZON`` is the bus that never
    comes, as far as the task and the reports up to the horizon tell)."""
    def caught(k: int, at_stop: frozenset[int], t: int) -> bool:
        return any(k <= j <= min(k + WINDOW, t) for j in at_stop)

    def mass(t: int, history: tuple[bool, ...]) -> list[tuple[int, float]]:
        return [(k, _likelihood(k, history, detect, fa, law)) for k in range(1, len(law) + 1)]

    index: dict[tuple, int] = {(0, "mid", (), frozenset()): 0}
    order = list(index)
    rows, cols, vals = [], [], []
    task, wet, undecided = [], [], []
    head = 0
    while head < len(order):
        t, w, hist, stop = order[head]
        head += 1
        if t == HORIZON:
            continue
        here = mass(t, hist)
        total = sum(p for _, p in here)
        share = 0.0 if w == "ditch" else sum(
            p for k, p in here if not caught(k, stop, t) and t < k + WINDOW) / total
        for a in STATION.actions(w):
            j = len(task)
            rows.append(index[(t, w, hist, stop)])
            cols.append(j)
            vals.append(1.0)
            win = wetness = 0.0
            for w2, pw in STATION.successors(w, a, frozenset()):
                stop2 = stop | {t + 1} if w2 == "st" else stop
                for seen in (True, False):
                    after = mass(t + 1, (*hist, seen))
                    p = pw * sum(q for _, q in after) / total
                    if p <= 0.0:
                        continue
                    o2 = (t + 1, w2, (*hist, seen), stop2)
                    if o2 not in index:
                        index[o2] = len(order)
                        order.append(o2)
                    rows.append(index[o2])
                    cols.append(j)
                    vals.append(-p)
                    wetness += p if w2 == "ditch" and w != "ditch" else 0.0
                    if t + 1 == HORIZON:
                        norm = sum(q for _, q in after)
                        win += p * sum(q for k, q in after if caught(k, stop2, HORIZON)) / norm
                        wetness += p * WET_LATER.get(w2, 0.0)
            task.append(win)
            wet.append(wetness)
            undecided.append(share)
    a_eq = sp.csr_array((vals, (rows, cols)), shape=(len(order), len(task)))
    live = [i for i, o in enumerate(order) if o[0] < HORIZON]
    b_eq = np.zeros(len(live))
    b_eq[0] = 1.0
    return {"a_eq": a_eq[live], "b_eq": b_eq, "task": np.array(task),
            "wet": np.array(wet), "steps": np.array(undecided)}


def storm(path: Path, prop: str) -> Fraction:
    """Storm's exact value of ``prop`` at the initial state of the DTMC at ``path``."""
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
    return exact_fraction(result.get_value(model.initial_states[0]))


#: the expected steps while the task is undecided and can be won, Storm's total reward
#: (``[C]``: a run the controller keeps for ever where the task is decided earns none)
STEPS = 'R{"steps"}=? [C]'


@pytest.fixture(scope="module")
def lp() -> dict[str, Any]:
    return every_step_lp(DETECT, FALSE_ALARM)


def test_the_lp_without_false_alarms_is_the_first_report_one() -> None:
    """The LP written here, at ``false_alarm = 0``, gives the first-report knowledge LP's
    optimum with the risk bounded (the reports after the first tell nothing more): a
    check of the LP itself."""
    lp = every_step_lp(DETECT, 0.0)
    first = knowledge_lp(DETECT)
    for rows in ([], [("wet", "<=", 0.1)]):
        assert best(lp, "task", True, rows) == pytest.approx(best(first, "task", True, rows),
                                                             abs=1e-8)


@pytest.mark.parametrize("task", sorted(TASKS))
def test_a_slack_constraint_gives_the_sensed_routes_answer(task: str) -> None:
    """A co-safe, a safety and an obligation task with a constraint that cannot bind
    (``P(F A) <= 1``): the constrained route's bracket is the ``sensed`` route's
    unconstrained one (checked there against the every-step expectimax)."""
    world, spec, own_law, _ = TASKS[task]
    model = Model.from_game(world, spec, events={"b": pmf(list(LAW))} if own_law else None,
                            sensors={"b": {"detect": 0.5, "false_alarm": 0.2}})
    plain = synthesize(model)
    r = synthesize(model, constraints=["P(F A) <= 1"])
    assert plain.route == "sensed" and r.route == "sensed-constrained"
    assert r.certified and plain.certified
    assert abs(r.lower - plain.lower) <= 1e-7 and abs(r.upper - plain.upper) <= 1e-7


def test_vanishing_false_alarms_give_the_camera_answer() -> None:
    """``false_alarm = 1e-8`` with a binding risk constraint: the answer of the camera
    without false alarms (itself the first-report knowledge LP's optimum)."""
    clean = synthesize(_model(0.0), constraints=["P(F wet) <= 0.1"])
    tiny = synthesize(_model(1e-8), constraints=["P(F wet) <= 0.1"])
    exact = best(knowledge_lp(DETECT), "task", True, [("wet", "<=", 0.1)])
    assert clean.lower - 1e-7 <= exact <= clean.upper + 1e-7
    assert tiny.route == "sensed-constrained" and tiny.certified
    assert abs(tiny.lower - clean.lower) <= 1e-6 and abs(tiny.upper - clean.upper) <= 1e-6


@pytest.mark.parametrize("bound", [0.1, 0.3])
def test_a_binding_constraint_equals_the_every_step_lp(bound: float, lp: dict[str, Any],
                                                       tmp_path: Path) -> None:
    """A risk constraint that binds: the certified bracket holds the every-step LP's
    optimum (unconstrained, the ``sensed`` route's answer), the false alarms lower it;
    Storm on the exported chain of the randomised controller gives ``lower`` and the
    risk at the bound."""
    from mitld_lp.running.chain import write_chain

    model = _model()
    r = synthesize(model, constraints=[f"P(F wet) <= {bound}"])
    assert r.route == "sensed-constrained" and r.certified
    exact = best(lp, "task", True, [("wet", "<=", bound)])
    top = best(lp, "task", True, [])
    assert exact < top - 1e-3  # the constraint binds
    plain = synthesize(model)
    assert plain.lower - 1e-7 <= top <= plain.upper + 1e-7
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7
    camera = best(knowledge_lp(DETECT), "task", True, [("wet", "<=", bound)])
    assert exact < camera - 1e-3  # the false alarms are read, and cost
    (c,) = r.constraints
    assert c.holds and Fraction(c.bounds[1]) <= Fraction(str(bound))
    path = write_chain(r, tmp_path / "c.drn")
    task = storm(path, 'P=? [F "accept"]')
    assert abs(task - Fraction(r.lower)) <= Fraction(1, 10**8)
    risk = storm(path, 'P=? [F "c1"]')
    assert risk <= Fraction(c.certified) + Fraction(1, 10**9)
    assert abs(float(risk) - bound) <= 1e-7  # the chain carries the risk, not less


def test_then_min_steps_on_the_chain_and_the_controller_runs(lp: dict[str, Any],
                                                             tmp_path: Path) -> None:
    """``then min-steps``: the optimum and the least expected steps among the policies
    reaching it are the every-step LP's; Storm's total reward of ``steps`` on the
    exported chain is the answer's; the randomised controller, simulated with every
    step's report drawn, succeeds at ``lower``'s rate, and saved and run by
    :mod:`mitld_lp.runtime` plays the live controller's actions."""
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.running.chain import write_chain
    from mitld_lp.runtime import load
    from mitld_lp.sensing.observe import simulate_sensed

    model = _model()
    r = synthesize(model, then="min-steps")
    assert r.route == "sensed-constrained" and r.certified
    top = best(lp, "task", True, [])
    fastest = best(lp, "steps", False, [("task", ">=", top - 1e-6)])
    slowest = best(lp, "steps", True, [("task", ">=", top - 1e-6)])
    assert fastest < slowest - 0.1  # the second objective matters here
    assert r.lower - 1e-7 <= top <= r.upper + 1e-7
    assert r.secondary == pytest.approx(fastest, abs=1e-5)
    path = write_chain(r, tmp_path / "c.drn")
    assert abs(storm(path, 'P=? [F "accept"]') - Fraction(r.lower)) <= Fraction(1, 10**8)
    assert float(storm(path, STEPS)) == pytest.approx(r.secondary, abs=1e-6)
    sim = simulate_sensed(model, r.controller, runs=2000, seed=5, max_steps=20)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.beyond_model == 0
    loaded = load(r.controller.save(tmp_path / "c.npz"))
    rng = np.random.default_rng(7)
    for run in range(30):
        r.controller.reset(seed=run)
        loaded.reset(seed=run)
        bus = int(rng.choice(len(PMF), p=PMF)) + 1
        w, reports = STATION.initial, frozenset()
        for t in range(HORIZON + 2):
            a = r.controller.act(Observation(w, reports=reports))
            assert loaded.act(w, reports=reports) == a
            if a is None:
                break
            succ = STATION.successors(w, a, frozenset())
            w = succ[int(rng.choice(len(succ), p=[p for _, p in succ]))][0]
            q = DETECT if t + 1 >= bus else FALSE_ALARM
            reports = frozenset({"b"}) if rng.random() < q else frozenset()
