"""Sensors with false alarms (``sensors.<a>.false_alarm > 0``) on event laws that surely
happen: the sensor reports or not at every step, with probability ``false_alarm`` before
step ``K + delay`` and ``detect`` from it on (docs/semantics.md, "Sensors that miss
events").  The information-state product keeps each hypothesis's count of reports before
its report was due (mitld_lp/sensing/rules.py, merge.py's ``Counts``); these tests check
its answers against an expectimax over every per-step report history in fractions
(tests/test_sensing_tasks.py's ``expectimax_every_step``), the ``false_alarm -> 0``
limit against the first-report construction, the exported chain with Storm, the running
controller's belief against Bayes' rule on the reports, and the refusals by name."""

from __future__ import annotations

import itertools
import json
import math
import subprocess
import sys
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_sensing_tasks import (
    PUSHED,
    STATION,
    ExplicitGame,
    avoided,
    both,
    caught,
    expectimax_every_step,
)

from mitld_lp import Model, synthesize
from mitld_lp.distributions import geometric, pmf

LAW = (0.25, 0.25, 0.5)  # the bus comes at step 1, 2 or 3: a law that surely happens
ON_LAW = f"D[pmf({', '.join(map(str, LAW))})] b & "
MASSES = tuple(Fraction(str(x)) for x in LAW)
HORIZON = 5  # every task below is decided by step 5 (the bus by step 3, windows of 1)


def _safe(world: ExplicitGame) -> Callable[..., Any]:
    return lambda trace, _: "ditch" not in trace


#: name: (world, spec, the spec's law given as events (None: in the spec), judge)
TASKS: dict[str, tuple[ExplicitGame, str, bool, Callable[..., Any]]] = {
    "co-safe": (PUSHED, ON_LAW + "F(b & F[0,1] A)", False, caught(PUSHED, "A", 1)),
    "safety": (PUSHED, "G !(b & A)", True, avoided(PUSHED, ["A"])),
    "obligation": (STATION, ON_LAW + "F(b & F[0,1] A) & G[0,5] !h", False,
                   both(caught(STATION, "A", 1), _safe(STATION))),
}


def _model(task: str, detect: float, false_alarm: float, delay: int = 0) -> Model:
    world, spec, own_law, _ = TASKS[task]
    return Model.from_game(world, spec, events={"b": pmf(list(LAW))} if own_law else None,
                           sensors={"b": {"detect": detect, "false_alarm": false_alarm,
                                          "delay": delay}})


def _within(r: Any, exact: Fraction) -> None:
    """The certified bracket holds the exact value, compared as fractions (the law is
    not truncated: the bracket is the solver's tolerance wide)."""
    assert r.certified, [c for c in r.checks if not c.passed]
    assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact), r.upper)
    assert r.upper - r.lower <= 1e-7


@pytest.mark.parametrize("task", sorted(TASKS))
@pytest.mark.parametrize("false_alarm, detect, delay", [
    ("0.2", "0.5", 0), ("0.1", "0.8", 1), ("0.3", "0.6", 2)])
def test_every_step_expectimax(task: str, false_alarm: str, detect: str, delay: int) -> None:
    """Both objectives of a co-safe, a safety and an obligation task, with and without a
    delay: the certified bracket holds the exact optimum over policies that see every
    step's report (the expectimax over report histories, in fractions)."""
    world, _, _, judge = TASKS[task]
    model = _model(task, float(detect), float(false_alarm), delay)
    for objective, sense in (("max", max), ("min", min)):
        exact = expectimax_every_step(world, MASSES, Fraction(detect), judge, HORIZON,
                                      false_alarm=Fraction(false_alarm), delay=delay,
                                      sense=sense)
        r = synthesize(model, objective=objective)
        assert r.route == "sensed"
        _within(r, exact)


def _expectimax_two(game: ExplicitGame, events: list[tuple[tuple[Fraction, ...], Fraction,
                                                            Fraction, int, str]],
                    horizon: int, sense: Callable[..., Fraction]) -> Fraction:
    """The best (``sense=min``: worst) probability, over policies that see the world
    state and every step's reports of each event (never the events), that the robot is
    at some event's place (the last item) the step it happens or the next; each event
    ``(masses of steps 1, 2, ..., detect, false_alarm, delay, place)``, its law surely
    happens, its sensor reporting at every step (``false_alarm`` before ``k + delay``)."""
    def won(trace: list[str], ks: tuple[int, ...]) -> bool:
        return any(any(place in game.propositions(trace[s])
                       for s in range(k, min(k + 1, len(trace) - 1) + 1))
                   for k, (_, _, _, _, place) in zip(ks, events, strict=True))

    def best(trace: list[str], alive: list[tuple[tuple[int, ...], Fraction]]) -> Fraction:
        t = len(trace) - 1
        if t == horizon:
            return sum((p for ks, p in alive if won(trace, ks)), Fraction(0))
        values = []
        for action in game.actions(trace[-1]):
            v = Fraction(0)
            for nxt, ps in game.successors(trace[-1], action, frozenset()):
                for seen in itertools.product((True, False), repeat=len(events)):
                    g = []
                    for ks, p in alive:
                        for k, (_, d, fa, delay, _), yes in zip(ks, events, seen,
                                                                 strict=True):
                            q = d if t + 1 >= k + delay else fa
                            p *= q if yes else 1 - q
                        if p:
                            g.append((ks, p * Fraction(str(ps))))
                    if g:
                        v += best([*trace, nxt], g)
            values.append(v)
        return sense(values)

    start = [(ks, math.prod((e[0][k - 1] for k, e in zip(ks, events, strict=True)),
                            start=Fraction(1)))
             for ks in itertools.product(*(range(1, len(e[0]) + 1) for e in events))]
    return best([game.initial], start)


@pytest.mark.parametrize("objective", ["max", "min"])
def test_two_sensed_events_one_with_false_alarms(objective: str) -> None:
    """Two buses at one station, one reported by a sensor with false alarms, one by a
    camera that misses (its first report alone, which gives the every-step optimum
    without false alarms): the bracket holds the expectimax over both sensors'
    every-step reports, in fractions (the maximum is 0.87075 here, 0.875 without the
    false alarms: they are read)."""
    half = (Fraction(1, 2), Fraction(1, 2))
    spec = ("(D[pmf(0.5, 0.5)] b1 & F(b1 & F[0,1] A)) | "
            "(D[pmf(0.5, 0.5)] b2 & F(b2 & F[0,1] A))")
    model = Model.from_game(PUSHED, spec, objective=objective,
                            sensors={"b1": {"detect": 0.8, "false_alarm": 0.3},
                                     "b2": {"detect": 0.6}})
    exact = _expectimax_two(PUSHED, [(half, Fraction(4, 5), Fraction(3, 10), 0, "A"),
                                     (half, Fraction(3, 5), Fraction(0), 0, "A")], 3,
                            max if objective == "max" else min)
    _within(synthesize(model), exact)


def test_false_alarms_change_the_optimum_and_vanish_in_the_limit() -> None:
    """The reports after the first are read: with false alarms the obligation's optimum
    is the every-step expectimax's, below the first-report answer (the route without
    false alarms, today's construction, and its own expectimax); as ``false_alarm -> 0``
    the answer tends to that one (continuous in ``false_alarm``: within ``1e-6`` at
    ``1e-8``)."""
    world, _, _, judge = TASKS["obligation"]
    clean = synthesize(_model("obligation", 0.5, 0.0))
    exact_clean = expectimax_every_step(world, MASSES, Fraction(1, 2), judge, HORIZON)
    _within(clean, exact_clean)
    noisy = synthesize(_model("obligation", 0.5, 0.2))
    assert noisy.upper < clean.lower - 1e-3  # false alarms blur what the reports say
    tiny = synthesize(_model("obligation", 0.5, 1e-8))
    assert abs(tiny.lower - clean.lower) <= 1e-6 and abs(tiny.upper - clean.upper) <= 1e-6


def _storm(path: Path, formula: str) -> Fraction:
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties(formula)[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


@pytest.mark.parametrize("world, spec, delay", [(PUSHED, "F(b & F[0,1] A)", 0),
                                                (STATION, "F(b & F[0,2] A) & G[0,8] !h", 1)])
def test_exported_chain_checked_by_storm(world: ExplicitGame, spec: str, delay: int,
                                         tmp_path: Path) -> None:
    """A geometric law (truncated; its tail counted as failure in ``lower``) with a
    false-alarm sensor, with and without a delay: ``export --chain``'s controlled chain, built from
    the true dynamics (per-step reports drawn from the true event time) and the
    controller's own tables, gives in Storm the controller's ``lower`` (to the DRN's
    decimals), inside the certified bracket; so does the decision tree ``export --tree``
    writes, run as the controller."""
    from mitld_lp.running.chain import write_chain
    from mitld_lp.running.tree import tree_controller, tree_of

    model = Model.from_game(world, spec, events={"b": geometric(0.4)},
                            sensors={"b": {"detect": 0.7, "false_alarm": 0.15, "delay": delay}},
                            epsilon=1e-3)
    r = synthesize(model)
    assert r.certified and r.route == "sensed"
    value = _storm(write_chain(r, tmp_path / "c.drn"), 'P=? [F "accept"]')
    assert abs(value - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert Fraction(r.lower) - Fraction(1, 10**9) <= value <= Fraction(r.upper)
    # export --tree: the tree over the world's variables and the memory, run as the
    # controller, has the same chain value
    tree = tree_controller(r, tree_of(r))
    assert _storm(write_chain(r, tmp_path / "t.drn", controller=tree),
                  'P=? [F "accept"]') == value


def _posterior(history: list[bool], detect: Fraction, fa: Fraction, delay: int
               ) -> dict[int, Fraction]:
    """Bayes' rule on the reports of steps ``1..t`` alone: the law's prior on ``k`` times
    each step's ``fa`` or ``detect`` (before or from ``k + delay``), normalised."""
    t = len(history)
    out = {}
    for k, mass in enumerate(MASSES, start=1):
        if mass == 0:
            continue
        p = mass
        for s, seen in enumerate(history, start=1):
            q = detect if s >= k + delay else fa
            p *= q if seen else 1 - q
        out[k] = p
    # the hypotheses not happened by t share one value of the info state: "not yet"
    merged: dict[int, Fraction] = {}
    for k, p in out.items():
        key = k if k <= t else 0
        merged[key] = merged.get(key, Fraction(0)) + p
    return merged


def test_the_running_controller_reads_every_report(tmp_path: Path) -> None:
    """On drawn runs (true bus time and every step's report drawn from the semantics):
    the controller's information state holds, hypothesis by hypothesis, Bayes' posterior
    on the reports so far (the hypotheses still undecided, renormalised); the controller
    saved and run by :mod:`mitld_lp.runtime` and by ``mitld-lp run`` plays the policy's
    action at each of those states."""
    from mitld_lp.controllers.observation import Observation
    from mitld_lp.runtime import load

    detect, fa, delay = Fraction(7, 10), Fraction(1, 5), 1
    model = _model("obligation", float(detect), float(fa), delay)
    r = synthesize(model)
    mdp, policy = r.mdp, r.part.lower_model.policy
    saved = r.controller.save(tmp_path / "c.npz")
    loaded = load(saved)
    rng = np.random.default_rng(5)
    game = model.game
    checked, lines_of_run = 0, []
    for _ in range(25):
        k = int(rng.choice([1, 2, 3], p=list(LAW)))
        r.controller.reset()
        loaded.reset()
        s, history, reports, lines = game.initial, [], frozenset(), []
        for _step in range(HORIZON + 1):
            action = r.controller.act(Observation(s, reports=reports))
            lines.append({"state": s, "reports": sorted(reports)})
            assert loaded.act(s, reports=reports) == action
            memory = r.controller.memory
            if action is None or not isinstance(memory, int):
                break
            assert action == mdp.action_name(int(policy[memory]))
            state = mdp.states[memory]
            exact = _posterior(history, detect, fa, delay)
            kept = {times[0]: w for (times, _), w in zip(state.hypotheses, state.weights,
                                                         strict=True)}
            total = sum(exact[x] for x in kept)
            for x, w in kept.items():
                assert abs(w - float(exact[x] / total)) <= 1e-9, (history, kept, exact)
            checked += 1
            t = len(history) + 1
            seen = bool(rng.random() < float(detect if t >= k + delay else fa))
            history.append(seen)
            reports = frozenset({"b"}) if seen else frozenset()
            events = frozenset({"b"}) if t == k else frozenset()
            succ = game.successors(s, action, events)
            s = succ[int(rng.choice(len(succ), p=[p for _, p in succ]))][0]
        lines_of_run.append((lines, r.controller))
    assert checked > 50
    lines = lines_of_run[0][0]
    run = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(saved)],
                         input="".join(json.dumps(x) + "\n" for x in lines),
                         capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0, run.stderr
    r.controller.reset()
    expected = [r.controller.act(Observation(x["state"], reports=frozenset(x["reports"])))
                for x in lines]
    assert [json.loads(x)["action"] for x in run.stdout.splitlines()] == expected


def test_simulation_draws_false_alarms_within_the_bracket() -> None:
    """Rollouts that draw every step's report (false alarms before ``K + delay``) land
    on the controller's certified value."""
    from mitld_lp.sensing.observe import simulate_sensed

    model = _model("obligation", 0.9, 0.3)  # without the false alarms drawn: 0.613
    r = synthesize(model)
    sim = simulate_sensed(model, r.controller, runs=4000, seed=3, max_steps=20)
    sigma = (r.lower * (1 - r.lower) / sim.runs) ** 0.5
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.beyond_model == 0
