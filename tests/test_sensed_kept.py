"""Tasks with a safety part (safety, obligation; a co-safe task's minimum, solved as its
complement's maximum) seen through a sensor that misses its event, with a constraint or
``then`` (the ``sensed-constrained`` route's *keep*, :mod:`mitld_lp.routes.sensed_kept`),
against an occupancy LP over the robot's knowledge written here from the semantics
(docs/semantics.md) and solved by scipy's linprog: the robot knows the step, its world
state, the step of the bus's first report (if any) and the steps it stood at the stop;
the hidden scenarios (bus step, report step) are enumerated with their probabilities
and the task and the constraint are judged on the trace -- no automaton, no hazards, no
information states, no end components.  The controller's chain, checked by Storm,
gives ``lower`` and meets each constraint's bound."""

from __future__ import annotations

from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from test_sensed_constrained import (  # the bus at step 1, 2, 3 or 4; the horizon 6
    HORIZON,
    PMF,
    WINDOW,
    Knowledge,
    best,
    consistent,
    flow_equations,
    scenarios,
)
from test_sensing_tasks import MIXED, PUSHED, STATION

from mitld_lp import Model, synthesize
from mitld_lp.distributions import pmf
from mitld_lp.running.chain import chain_of, write_chain

LAW = f"D[pmf({', '.join(map(str, PMF))})] b & "
#: ``G !h`` on STATION from each world state at the horizon, at best: from the stop go
#: back (0.8), then wait at mid for ever
KEPT_AFTER = {"mid": 1.0, "st": 0.8, "ditch": 0.0}

Judge = Callable[[str, int, frozenset[int], bool], float]


def knowledge_lp(game, detect: float, task: Judge, cons: Judge) -> dict:
    """The occupancy LP over the knowledge ``(t, world, report step, steps at the stop,
    fell)``: one variable per (knowledge, action) for ``t < HORIZON``; per variable the
    probability that it leads to a knowledge at the horizon, times the chance (over the
    scenarios consistent with it) that the task holds, and likewise the constraint's
    formula.  ``task(world, k, stops, fell)``: whether (or with what chance, the best
    continuation) the task holds for bus step ``k``."""
    scen = scenarios(detect)
    intern = Knowledge((0, game.initial, None, frozenset(), False))
    owners, win, con, flows = [], [], [], []
    head = 0
    while head < len(intern.order):
        here = intern.order[head]
        t, w, r, stops, fell = here
        head += 1
        if t == HORIZON:
            continue
        total = sum(p for _, p in consistent(scen, t, r))
        for a in game.actions(w):
            owners.append(intern(here))
            flow, v_task, v_con = [], 0.0, 0.0
            for w2, pw in game.successors(w, a, frozenset()):
                stops2 = frozenset(stops | {t + 1} if "A" in game.propositions(w2) else stops)
                fell2 = fell or "h" in game.propositions(w2)
                for r2 in ([r] if r is not None else [t + 1, None]):
                    post = consistent(scen, t + 1, r2)
                    norm = sum(p for _, p in post)
                    pr = pw * norm / total
                    if pr <= 0:
                        continue
                    flow.append((intern((t + 1, w2, r2, stops2, fell2)), pr))
                    if t + 1 == HORIZON:
                        v_task += pr * sum(p * task(w2, k, stops2, fell2) for k, p in post) / norm
                        v_con += pr * sum(p * cons(w2, k, stops2, fell2) for k, p in post) / norm
            win.append(v_task)
            con.append(v_con)
            flows.append(flow)
    a_eq, b_eq = flow_equations(intern.order, owners, flows)
    return {"a_eq": a_eq, "b_eq": b_eq, "task": np.array(win), "con": np.array(con)}


def optimum(lp: dict, maximise: bool, sense: str | None = None, bound: float = 0.0
            ) -> float:
    """The best (``maximise``) or least task probability, with the constraint's
    probability ``sense`` ``bound`` if given."""
    return best(lp, "task", maximise, [] if sense is None else [("con", sense, bound)])


def caught(k: int, stops: frozenset[int]) -> bool:
    """``F(b & F[0,2] A)`` for bus step ``k``."""
    return any(k <= j <= k + WINDOW for j in stops)


def storm(path: Path, prop: str) -> Fraction:
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


def _checked_by_storm(r, tmp_path: Path, *, complement: bool = False) -> None:
    """The controller's chain: its task probability is ``lower`` (for a minimum the
    complement's, ``1 - upper``: the chain follows the complement's automaton), its runs
    end, and each constraint's probability meets its certified bound."""
    path = write_chain(r, tmp_path / "chain.drn")
    chain = chain_of(r)
    rows = chain.matrix.sum(axis=1)
    assert np.abs(rows - 1).max() < 1e-12
    labels = set().union(*chain.labels)
    task = float(storm(path, 'P=? [F "accept"]'))
    assert task == pytest.approx(1 - r.upper if complement else r.lower, abs=1e-9)
    # every run ends but for the interior-point solver's negligible flows, which may
    # trap a run among information states (valued as staying there: the task lost)
    assert storm(path, 'P=? [F "done"]') >= 1 - Fraction(1, 10**9)
    for i, c in enumerate(r.constraints, start=1):
        got = storm(path, f'P=? [F "c{i}"]') if f"c{i}" in labels else Fraction(0)
        if c.constraint.sense == "<=":
            assert got <= Fraction(c.certified) <= Fraction(c.constraint.bound)
        else:
            assert got >= Fraction(c.certified) >= Fraction(c.constraint.bound)


@pytest.mark.parametrize(("detect", "bound"), [(0.5, 0.5), (0.0, 0.3), (0.8, 0.7)])
def test_obligation_with_a_constraint_equals_the_knowledge_lp(detect: float, bound: float,
                                                              tmp_path: Path) -> None:
    """``F(b & F[0,2] A) & G !h`` (catch the bus, never fall into the ditch, for ever),
    at least ``bound`` of being at the stop by step 1 (too early for the bus, mostly):
    the keep (wait at mid for ever once the bus is caught on every hypothesis) is the
    only way to win."""
    model = Model.from_game(STATION, LAW + "F(b & F[0,2] A) & G !h",
                            sensors={"b": {"detect": detect}})
    r = synthesize(model, constraints=[f"P(F[0,1] A) >= {bound}"])
    assert r.route == "sensed-constrained" and r.certified, r.summary()["failed_checks"]
    lp = knowledge_lp(STATION, detect,
                      lambda w, k, stops, fell: caught(k, stops) * KEPT_AFTER[w],
                      lambda w, k, stops, fell: float(bool(stops & {0, 1})))
    exact = optimum(lp, True, ">=", bound)
    assert exact < optimum(lp, True) - 1e-3  # the constraint binds
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7 and r.upper - r.lower < 1e-6
    (c,) = r.constraints
    assert c.holds and Fraction(c.bounds[0]) >= Fraction(bound)
    _checked_by_storm(r, tmp_path)


@pytest.mark.parametrize("detect", [0.5, 0.0])
def test_safety_task_then_min_steps_keeps_the_best_probability(detect: float,
                                                               tmp_path: Path) -> None:
    """``G !(b & A)`` then the fewest expected steps: the probability is the knowledge
    LP's best (the second objective may not cost it), and the chain gives ``lower``."""
    model = Model.from_game(STATION, "G !(b & A)", events={"b": pmf(list(PMF))},
                            sensors={"b": {"detect": detect}})
    r = synthesize(model, then="min-steps")
    assert r.route == "sensed-constrained" and r.certified, r.summary()["failed_checks"]
    lp = knowledge_lp(STATION, detect,
                      lambda w, k, stops, fell: float(k not in stops),
                      lambda w, k, stops, fell: 0.0)
    exact = optimum(lp, True)
    assert r.lower - 1e-5 <= exact <= r.upper + 1e-7  # then: the lexicographic tolerance
    _checked_by_storm(r, tmp_path)


def test_blind_safety_then_min_steps_takes_four_steps(tmp_path: Path) -> None:
    """``G !(b & A)`` seen blind (``detect = 0``), then the fewest expected steps.  By
    hand: the blind robot knows only the step, and the bus may come at steps 1 to 4, so
    its task holds surely only if it is never at ``A`` before step 4; it may stop (keep)
    only once no hypothesis is open, at step 4: 4 steps, waiting.  A go before then is
    at ``A`` when the bus comes with probability at least 0.8 x 0.25, so the
    lexicographic tolerance 1e-6 buys at most 5e-6 of it, 4 steps each: E(steps) is in
    [4 - 2e-5, 4].  The interior point's circulation on a ditch's self-loop, reached by
    a path of tiny flows, left the controller there for ever (steps inf, certified);
    Storm's expected steps on the exported chain are the answer's."""
    model = Model.from_game(STATION, "G !(b & A)", events={"b": pmf(list(PMF))},
                            sensors={"b": {"detect": 0.0}})
    r = synthesize(model, then="min-steps")
    assert r.route == "sensed-constrained" and r.certified, r.summary()["failed_checks"]
    assert 4 - 2e-5 <= r.part.steps <= 4 + 1e-9 and 4 - 2e-5 <= r.secondary <= 4 + 1e-9
    steps = storm(write_chain(r, tmp_path / "steps.drn"), 'R{"steps"}=? [F "done"]')
    assert float(steps) == pytest.approx(r.secondary, abs=1e-6)
    _checked_by_storm(r, tmp_path)


@pytest.mark.parametrize(("spec", "law", "sensor", "route", "steps"), [
    ("G !(b & A)", [0.5, 0.5], None, "constrained", 1.5),
    ("G !(b & A)", [0.5, 0.5], {"detect": 1.0}, "constrained", 1.5),
    ("G !(b & A)", [0.5, 0.5], {"detect": 1 - 1e-9}, "sensed-constrained", 1.5),
    ("G !(b & A)", [0.5, 0.5], {"detect": 1.0, "delay": 1}, "sensed-constrained", 2.5),
    ("G !(b & A)", [0.0, 1.0], {"detect": 1.0, "delay": 1}, "sensed-constrained", 3.0),
    ("G !(b & A)", [0.0, 1.0], {"detect": 0.5}, "sensed-constrained", 3.0),
    ("G !(b & A)", [0.5, 0.5], {"detect": 0.5, "delay": 1}, "sensed-constrained", 3.5),
    ("!A U b", [0.5, 0.5], {"detect": 1.0, "delay": 1}, "sensed-constrained", 1.5),
])
def test_then_min_steps_counts_until_the_reports_are_in(
        spec: str, law: list[float], sensor: dict | None, route: str, steps: float) -> None:
    """``G !(b & A)`` then the fewest expected steps, the bus at step 1 or 2 (or surely
    at 2).  By hand: the robot waits at ``mid`` (never at ``A``: probability 1); seen,
    its task is kept from the bus's step ``k`` on (``mid``'s wait an end component
    then), so E(steps) = E(k) = 1.5, with a perfect sensor and with one that (almost)
    never misses alike; with a report ``delay`` steps late it stops once the report is
    in, at ``k + 1`` (docs/constraints.md, "With a sensor"): 2.5, and 3 for the bus
    surely at step 2, although the law already tells the robot then.  A sensor that
    misses (``detect = 0.5``) reports at each later step with that chance, a wait of
    ``(1 - detect) / detect = 1`` step on average: E(k) + delay + 1.  The lexicographic
    tolerance (1e-6 of probability) may buy a few steps' worth of 1e-6.  The co-safe
    ``!A U b`` is decided at ``k`` on every hypothesis, the late report adding nothing:
    1.5."""
    kw = {"sensors": {"b": sensor}} if sensor else {}
    model = Model.from_game(STATION, spec, events={"b": pmf(law)}, **kw)
    r = synthesize(model, then="min-steps")
    assert r.route == route and r.certified, r.summary()["failed_checks"]
    assert r.upper >= 1 - 1e-9 and r.lower >= 1 - 2e-6
    assert r.part.steps == pytest.approx(steps, abs=2e-5)


def test_a_trapped_policy_is_not_certified(monkeypatch: pytest.MonkeyPatch) -> None:
    """The same problem with the trapped states left as the interior point's policy
    reads them (the mending switched off): its chain stays undecided for ever, and the
    answer says so and is not certified (it said inf steps, certified)."""
    monkeypatch.setattr("mitld_lp.solvers.constrained._exits_kept",
                        lambda merged, prob, stay, *rest: (prob, stay))
    model = Model.from_game(STATION, "G !(b & A)", events={"b": pmf(list(PMF))},
                            sensors={"b": {"detect": 0.0}})
    r = synthesize(model, then="min-steps")
    assert r.part.steps == float("inf") and not r.certified
    assert "expected steps" in " ".join(r.summary()["failed_checks"])


@pytest.mark.parametrize(("detect", "bound"), [(0.5, 0.35), (0.0, 0.35), (0.9, 0.5)])
def test_minimum_with_a_constraint_equals_the_knowledge_lp(detect: float, bound: float,
                                                           tmp_path: Path) -> None:
    """The least probability of catching the bus in PUSHED (waiting at mid pushes the
    robot to the stop half the time), the robot falling into the ditch by the horizon
    with at most ``bound``: solved as the complement's (a safety task's) maximum with
    the constraint, the keep where every hypothesis has escaped the bus."""
    model = Model.from_game(PUSHED, LAW + "F(b & F[0,2] A)", objective="min",
                            sensors={"b": {"detect": detect}})
    r = synthesize(model, constraints=[f"P(F[0,{HORIZON}] h) <= {bound}"])
    assert r.route == "sensed-constrained" and r.status == "optimal"
    assert r.complemented
    lp = knowledge_lp(PUSHED, detect,
                      lambda w, k, stops, fell: float(caught(k, stops)),
                      lambda w, k, stops, fell: float(fell))
    exact = optimum(lp, False, "<=", bound)
    assert exact > optimum(lp, False) + 1e-3  # the constraint binds
    assert 0 < exact < 1
    assert r.certified, r.summary()["failed_checks"]
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7 and r.upper - r.lower < 1e-6
    (c,) = r.constraints
    assert c.holds and Fraction(c.bounds[1]) <= Fraction(bound)
    _checked_by_storm(r, tmp_path, complement=True)


def mixed_lp(detect: float) -> dict:
    """The occupancy LP over what the robot knows in MIXED (``(F(b & A) & G !h) | F c``,
    the bus at step 1 or 2): the world trace and the report step to step 2, then one of
    two ways to go on for ever: wait (won where the robot stood at ``A`` the step the
    bus came) or try for ``c`` (0.4; else the ditch), or nothing left to choose in
    ``cz`` (won) or the ditch (lost).  Per variable: the task's and the ditch's
    probability."""
    scen = [(k, r, 0.5 * detect * (1 - detect) ** (r - k)) for k in (1, 2)
            for r in range(k, 3)] + [(k, None, 0.5 * (1 - detect) ** (3 - k)) for k in (1, 2)]
    scen = [x for x in scen if x[2] > 0]
    intern = Knowledge((0, ("mid",), None))
    owners, win, fell, flows = [], [], [], []
    head = 0
    while head < len(intern.order):
        here = intern.order[head]
        t, trace, r = here
        head += 1
        post = consistent(scen, t, r)
        norm = sum(p for _, p in post)
        w = trace[-1]
        if t == 2:  # the ways to go on for ever
            lost = "ditch" in trace
            caught = sum(p for k, p in post if trace[k] == "st") / norm
            ends = ([(0.0, 1.0)] if lost else [(1.0, 0.0)] if w == "cz" else
                    [(caught, 0.0), (0.4, 0.6)])
            for v_task, v_fell in ends:
                owners.append(intern(here))
                win.append(v_task)
                fell.append(v_fell)
                flows.append([])
            continue
        for a in MIXED.actions(w):
            owners.append(intern(here))
            flow = []
            for w2, pw in MIXED.successors(w, a, frozenset()):
                for r2 in ([r] if r is not None else [t + 1, None]):
                    pr = pw * sum(p for _, p in consistent(scen, t + 1, r2)) / norm
                    if pr > 0:
                        flow.append((intern((t + 1, (*trace, w2), r2)), pr))
            win.append(0.0)
            fell.append(0.0)
            flows.append(flow)
    n, m = len(intern.order), len(owners)
    a_eq = np.zeros((n, m))
    for j, (s, flow) in enumerate(zip(owners, flows, strict=True)):
        a_eq[s, j] += 1.0
        for s2, p in flow:
            a_eq[s2, j] -= p
    b_eq = np.zeros(n)
    b_eq[0] = 1.0
    return {"a_eq": a_eq, "b_eq": b_eq, "task": np.array(win), "con": np.array(fell)}


@pytest.mark.parametrize("detect", [0.5, 0.0])
def test_mixed_end_components_equal_the_knowledge_lp(detect: float, tmp_path: Path) -> None:
    """MIXED with at most 0.1 of falling into the ditch: a robot unsure whether it
    caught the bus waits for ever with one hypothesis kept safe and one waiting for
    ``c``; each hypothesis is safe everywhere or nowhere in that end component, so the
    keep there is worth the safe one's weight, exactly: the knowledge LP's optimum."""
    model = Model.from_game(MIXED, "(F(b & A) & G !h) | F c", events={"b": pmf([0.5, 0.5])},
                            sensors={"b": {"detect": detect}})
    r = synthesize(model, constraints=["P(F h) <= 0.1"])
    assert r.route == "sensed-constrained" and r.certified, r.summary()["failed_checks"]
    exact = optimum(mixed_lp(detect), True, "<=", 0.1)
    # the constraint binds where the camera tells the robot to try (blind, it waits)
    assert detect == 0 or exact < optimum(mixed_lp(detect), True) - 1e-3
    assert r.lower - 1e-7 <= exact <= r.upper + 1e-7 and r.upper - r.lower < 1e-6
    assert all(c.holds for c in r.constraints)
    _checked_by_storm(r, tmp_path)


@pytest.mark.parametrize("spec", ["(F(b & A) & G !h) | F c", "F(b & A) | F c"])
def test_then_with_a_trap_is_solved_and_bracketed(spec: str, tmp_path: Path) -> None:
    """``then`` in MIXED, whose ditch keeps ``F c`` open on the automaton for ever (the
    world never reaches ``c`` from it): no step counts where the task can no longer be
    won, so the robot may rest there (it was refused as infeasible).  Waiting for ever
    with an open hypothesis takes steps for ever, so with the safe part the policy
    does not, and the other bound credits it: a bracket holding the best probability;
    the chain gives ``lower`` and its expected steps are the answer's."""
    model = Model.from_game(MIXED, spec, events={"b": pmf([0.5, 0.5])},
                            sensors={"b": {"detect": 0.5}})
    r = synthesize(model, then="min-steps")
    assert r.status == "optimal" and r.certified, r.summary()["failed_checks"]
    top = optimum(mixed_lp(0.5), True) if "G" in spec else 0.7  # by hand: try at once
    assert r.lower - 1e-5 <= top <= r.upper + 1e-7
    _checked_by_storm(r, tmp_path)
    steps = storm(write_chain(r, tmp_path / "steps.drn"), 'R{"steps"}=? [F "done"]')
    assert float(steps) == pytest.approx(r.secondary, abs=1e-6)


def test_the_keeping_controller_runs_and_reloads(tmp_path: Path) -> None:
    """The obligation's controller, simulated on the true events (a run kept for ever
    counts as won, as the simulator counts a safe state at its last step): its success
    rate is the policy's exact value; saved and loaded, its chain is the live one's."""
    from mitld_lp import load_controller
    from mitld_lp.sensing.observe import simulate_sensed

    model = Model.from_game(STATION, LAW + "F(b & F[0,2] A) & G !h",
                            sensors={"b": {"detect": 0.5}})
    r = synthesize(model, constraints=["P(F[0,1] A) >= 0.5"])
    assert r.certified and any(d is not None and d.stay > 0
                               for d in r.controller.plan.decisions)  # it keeps
    sim = simulate_sensed(model, r.controller, runs=2000, seed=3, max_steps=30)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.beyond_model == 0
    loaded = load_controller(r.controller.save(tmp_path / "kept.npz"))
    live = storm(write_chain(r, tmp_path / "live.drn"), 'P=? [F "accept"]')
    assert storm(write_chain(r, tmp_path / "file.drn", controller=loaded),
                 'P=? [F "accept"]') == live
