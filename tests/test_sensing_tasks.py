"""Sensors that miss events with every task class, both objectives and laws that may
never happen, against an exhaustive expectimax over observation histories written here
from the semantics (docs/semantics.md, "Sensors that miss events"), in fractions: the
hidden scenarios (each event's step or never, its first report's step) enumerated with
their probabilities, the task judged on the finished trace by a Python predicate (no
automaton, no hazards, no information states), the best (or worst) observation-based
policy found by enumerating every history to a horizon past which the task is decided.
The certified bracket must hold that value."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from fractions import Fraction
from typing import Any

import pytest
from test_sensing import TWO  # two stations, one per bus

from mitld_lp import ExplicitGame, Model, synthesize
from mitld_lp.distributions import pmf

STATION = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"go": {"st": 0.8, "ditch": 0.2}, "wait": {"mid": 1.0}},
        "st": {"wait": {"st": 0.5, "ditch": 0.5}, "back": {"mid": 0.8, "ditch": 0.2}},
        "ditch": {"stay": {"ditch": 1.0}},
    },
    labels={"st": {"A"}, "ditch": {"h"}},
)
# waiting is not safe here: a minimum is not 0
PUSHED = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"go": {"st": 0.8, "ditch": 0.2}, "wait": {"mid": 0.5, "st": 0.5}},
        "st": {"wait": {"st": 0.5, "ditch": 0.5}, "back": {"mid": 0.8, "ditch": 0.2}},
        "ditch": {"stay": {"ditch": 1.0}},
    },
    labels={"st": {"A"}, "ditch": {"h"}},
)
Times = tuple[tuple[int | None, int | None], ...]
Judge = Callable[[Sequence[str], Times], "bool | Fraction"]


def scenarios(events: Sequence[tuple[Sequence[Fraction], Fraction]], horizon: int
              ) -> list[tuple[Times, Fraction]]:
    """Every hidden scenario to ``horizon``: per event ``(step or None for never, first
    report's step or None for none by the horizon)``, with its probability; ``events``:
    ``(masses of steps 1, 2, ..., detect)``, the rest of the mass is never."""
    per_event = []
    for masses, d in events:
        options: list[tuple[int | None, int | None, Fraction]] = []
        for k, mu in enumerate(masses, start=1):
            for r in range(k, horizon + 1):
                options.append((k, r, mu * d * (1 - d) ** (r - k)))
            options.append((k, None, mu * (1 - d) ** max(0, horizon - k + 1)))
        options.append((None, None, 1 - sum(masses, Fraction(0))))
        per_event.append([o for o in options if o[2] > 0])
    return [(tuple((k, r) for k, r, _ in combo), math.prod(p for _, _, p in combo))
            for combo in itertools.product(*per_event)]


def expectimax(game: ExplicitGame, events: Sequence[tuple[Sequence[Fraction], Fraction]],
               judge: Judge, horizon: int, sense: Callable[..., Fraction] = max,
               terminal: Callable[..., Fraction] | None = None) -> Fraction:
    """The best (``sense=min``: the worst) probability over policies that see the world
    state and the reports of each step (never the events) that ``judge(trace, times)``
    holds, ``trace`` the world states of steps ``0..horizon`` (a judge may return the
    probability that the task holds, the best continuation from the horizon on; or
    ``terminal(trace, alive)`` the best continuation given the scenarios left)."""

    def best(trace: list[str], alive: list[tuple[Times, Fraction]]) -> Fraction:
        t = len(trace) - 1
        if t == horizon and terminal is not None:
            return terminal(trace, alive)
        if t == horizon:
            return sum((p * judge(trace, times) for times, p in alive), Fraction(0))
        values = []
        for action in game.actions(trace[-1]):
            v = Fraction(0)
            for nxt, ps in game.successors(trace[-1], action, frozenset()):
                groups: dict[tuple[bool, ...], list[tuple[Times, Fraction]]] = {}
                for times, p in alive:  # the observation: which events are reported now
                    seen = tuple(r == t + 1 for _, r in times)
                    groups.setdefault(seen, []).append((times, p * Fraction(str(ps))))
                v += sum((best([*trace, nxt], g) for g in groups.values()), Fraction(0))
            values.append(v)
        return sense(values)

    return best([game.initial], scenarios(events, horizon))


def _has(game: ExplicitGame, state: str, prop: str) -> bool:
    return prop in game.propositions(state)


def avoided(game: ExplicitGame, props: Sequence[str]) -> Judge:
    """``G !(b_i & props[i])`` for every event ``i``: never at its place the step it
    happens."""
    def judge(trace: Sequence[str], times: Times) -> bool:
        return not any(k is not None and k < len(trace) and _has(game, trace[k], p)
                       for (k, _), p in zip(times, props, strict=True))
    return judge


def caught(game: ExplicitGame, prop: str, window: int) -> Judge:
    """``F(b & F[0,window] prop)``: at ``prop`` within ``window`` steps of the event."""
    def judge(trace: Sequence[str], times: Times) -> bool:
        k = times[0][0]
        return k is not None and any(_has(game, trace[t], prop)
                                     for t in range(k, min(k + window, len(trace) - 1) + 1))
    return judge


def visited_by(game: ExplicitGame, prop: str, deadline: int) -> Judge:
    def judge(trace: Sequence[str], times: Times) -> bool:
        return any(_has(game, s, prop) for s in trace[:deadline + 1])
    return judge


def both(*judges: Judge) -> Judge:
    return lambda trace, times: math.prod(Fraction(j(trace, times)) for j in judges)


def _frac(xs: Sequence[float]) -> tuple[Fraction, ...]:
    return tuple(Fraction(str(x)) for x in xs)


def _within(r: Any, exact: Fraction, width: float = 1e-7) -> None:
    """The certified bracket holds the exact value (compared as fractions: no
    tolerance), and is no wider than ``width``."""
    assert r.certified, [c for c in r.checks if not c.passed]
    assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, float(exact), r.upper)
    assert r.upper - r.lower <= width


PMF = (0.25, 0.25, 0.25, 0.25)  # the bus comes at step 1, 2, 3 or 4


@pytest.mark.parametrize("detect", [0.0, 0.5, 0.9])
def test_safety_task_equals_expectimax(detect: float) -> None:
    """``G !(b & A)``: never at the station the step the bus passes (a law without
    ``F b``: ``events=``); waiting at ``mid`` is safe, so the best is 1 -- the worst
    (objective min, solved as the complement's maximum) is the interesting one, and the
    obligation below is the interesting maximum."""
    model = Model.from_game(STATION, "G !(b & A)", events={"b": pmf(list(PMF))},
                            sensors={"b": {"detect": detect}})
    judge = avoided(STATION, ["A"])
    events = [(_frac(PMF), Fraction(str(detect)))]
    best = synthesize(model)
    assert best.route == "sensed"
    _within(best, expectimax(STATION, events, judge, horizon=4))
    worst = synthesize(model, objective="min")
    exact = expectimax(STATION, events, judge, horizon=4, sense=min)
    _within(worst, exact)
    assert 0 < exact < 1


@pytest.mark.parametrize("detect", [0.0, 0.5, 1.0])
def test_obligation_task_equals_expectimax(detect: float) -> None:
    """``F(b & F[0,2] A) & G !h``: catch the bus at the station, never fall into the
    ditch, for ever after (the best continuation from the horizon: back from the
    station with 0.8, waiting at ``mid`` for ever); both objectives of the bounded
    ``F(b & F[0,2] A) & G[0,6] !h``."""
    law = f"D[pmf({', '.join(map(str, PMF))})] b & "
    sensors = {"b": {"detect": detect}} if detect < 1 else None
    events = [(_frac(PMF), Fraction(str(detect)))]
    model = Model.from_game(STATION, law + "F(b & F[0,2] A) & G !h", sensors=sensors)
    r = synthesize(model)
    assert r.route == ("sensed" if sensors else "plain")
    _within(r, expectimax(STATION, events, both(caught(STATION, "A", 2), kept(STATION)),
                          horizon=6))
    if sensors:
        said = next(c.detail for c in r.checks if "observation-based acceptance" in c.name)
        assert said.startswith("exact")
    bounded = Model.from_game(STATION, law + "F(b & F[0,2] A) & G[0,6] !h", sensors=sensors)
    judge = both(caught(STATION, "A", 2), lambda trace, _: "ditch" not in trace)
    for objective, sense in (("max", max), ("min", min)):
        _within(synthesize(bounded, objective=objective),
                expectimax(STATION, events, judge, horizon=6, sense=sense))


def kept(game: ExplicitGame) -> Judge:
    """``G !h`` in :data:`STATION`, the trace and its best continuation: never in the
    ditch to the horizon, then from the station back to ``mid`` (0.8) and waiting."""
    def judge(trace: Sequence[str], times: Times) -> Fraction:
        if any(_has(game, s, "h") for s in trace):
            return Fraction(0)
        return Fraction(4, 5) if trace[-1] == "st" else Fraction(1)
    return judge


def test_obligation_example_is_not_degenerate() -> None:
    judge = both(caught(STATION, "A", 2), kept(STATION))

    def value(d: str) -> Fraction:
        return expectimax(STATION, [(_frac(PMF), Fraction(d))], judge, horizon=6)

    assert value("0") < value("0.5") < value("1")


@pytest.mark.parametrize("detect", [0.0, 0.5])
def test_cosafe_minimum_equals_expectimax(detect: float) -> None:
    """``objective = "min"`` of a co-safe task, minimised on its own automaton (the
    plain route's way), where waiting is not safe."""
    spec = f"D[pmf({', '.join(map(str, PMF))})] b & F(b & F[0,2] A)"
    model = Model.from_game(PUSHED, spec, sensors={"b": {"detect": detect}})
    r = synthesize(model, objective="min")
    assert r.route == "sensed" and r.sense == "min"
    exact = expectimax(PUSHED, [(_frac(PMF), Fraction(str(detect)))], caught(PUSHED, "A", 2),
                       horizon=6, sense=min)
    _within(r, exact)
    assert 0 < exact


NEVER = (0.3, 0.3)  # the bus comes at step 1 or 2, or never (0.4)


@pytest.mark.parametrize("detect", [0.0, 0.5, 0.8])
def test_law_that_may_never_happen_equals_expectimax(detect: float) -> None:
    """A sensed bus that may never come: "never" is a hypothesis of its own, the
    misses cut after ``R`` of them; the bracket holds the exact value and is no wider
    than the epsilon achieved (both cuts counted in it)."""
    model = Model.from_game(STATION, "D[pmf(0.3, 0.3)] b & F(b & F[0,2] A)",
                            sensors={"b": {"detect": detect}}, epsilon=1e-4)
    r = synthesize(model)
    exact = expectimax(STATION, [(_frac(NEVER), Fraction(str(detect)))],
                       caught(STATION, "A", 2), horizon=4)
    assert r.route == "sensed"
    _within(r, exact, width=r.sta.epsilon_achieved + 1e-9)
    assert r.sta.epsilon_achieved <= 1e-4
    assert exact < Fraction(6, 10)  # the bus comes with 0.6 at most
    safety = Model.from_game(PUSHED, "G !(b & A)", events={"b": pmf(list(NEVER))},
                             sensors={"b": {"detect": detect}}, epsilon=1e-4)
    judge = avoided(PUSHED, ["A"])
    events = [(_frac(NEVER), Fraction(str(detect)))]
    for objective, sense in (("max", max), ("min", min)):
        r = synthesize(safety, objective=objective)
        _within(r, expectimax(PUSHED, events, judge, horizon=2, sense=sense),
                width=r.sta.epsilon_achieved + 1e-9)


def test_two_sensed_events_safety_equals_expectimax() -> None:
    """Two buses, each with its camera: reach ``A`` or ``B`` by step 4, never at
    either the step its bus passes."""
    spec = "F[0,4] (A | B) & G !(b1 & A) & G !(b2 & B)"
    laws = {"b1": pmf([0.5, 0.5]), "b2": pmf([0.3, 0.3, 0.4])}
    model = Model.from_game(TWO, spec, events=laws,
                            sensors={"b1": {"detect": 0.6}, "b2": {"detect": 0.3}})
    r = synthesize(model)
    events = [(_frac((0.5, 0.5)), Fraction("0.6")), (_frac((0.3, 0.3, 0.4)), Fraction("0.3"))]

    def reach(trace: Sequence[str], times: Times) -> bool:
        return any(_has(TWO, s, "A") or _has(TWO, s, "B") for s in trace[:5])

    judge = both(reach, avoided(TWO, ["A", "B"]))
    _within(r, expectimax(TWO, events, judge, horizon=4))


MIXED = ExplicitGame(
    initial="mid",
    transitions={
        "mid": {"go": {"st": 1.0}, "wait": {"mid": 1.0}, "try": {"cz": 0.4, "ditch": 0.6}},
        "st": {"back": {"mid": 1.0}},
        "cz": {"stay": {"cz": 1.0}},
        "ditch": {"stay": {"ditch": 1.0}},
    },
    labels={"st": {"A"}, "cz": {"c"}, "ditch": {"h"}},
)


@pytest.mark.parametrize("detect", [0.0, 0.5])
def test_mixed_end_components_equal_expectimax(detect: float, tmp_path: Any) -> None:
    """``(F(b & A) & G !h) | F c``: a robot that was at ``A`` when the bus came is done
    by waiting for ever, one that was not needs ``c`` (reached by a risky try). A robot
    unsure which waits for ever with both hypotheses alive: one persistent, one not
    (for the blind robot waiting, 1/2, beats trying, 0.4). Such an end component is
    credited with its persistent hypotheses' weight, the controller's value is found
    on its chain, and Storm's value of the exported chain is that value."""
    from mitld_lp.running.chain import write_chain

    model = Model.from_game(MIXED, "(F(b & A) & G !h) | F c", events={"b": pmf([0.5, 0.5])},
                            sensors={"b": {"detect": detect}})
    r = synthesize(model)

    def terminal(trace: Sequence[str], alive: list[tuple[Times, Fraction]]) -> Fraction:
        """After the bus (step 1 or 2): the best of waiting for ever (the caught
        scenarios win) and trying once for ``c`` (0.4 of every scenario)."""
        if "ditch" in trace:
            return Fraction(0)
        total = sum((p for _, p in alive), Fraction(0))
        if trace[-1] == "cz":
            return total
        won = sum((p for times, p in alive if trace[times[0][0]] == "st"), Fraction(0))
        return max(won, Fraction(2, 5) * total)

    exact = expectimax(MIXED, [(_frac((0.5, 0.5)), Fraction(str(detect)))],
                       lambda *_: True, horizon=2, terminal=terminal)
    _within(r, exact)
    said = next(c.detail for c in r.checks if "observation-based acceptance" in c.name)
    assert said.startswith("bracketed")
    assert detect > 0 or exact == Fraction(1, 2)
    chain = _storm(write_chain(r, tmp_path / "mixed.drn"), 'P=? [F "accept"]')
    assert Fraction(r.lower) <= chain <= Fraction(r.upper)


def _storm(path: Any, formula: str) -> Fraction:
    stormpy = pytest.importorskip("stormpy")
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties(formula)[0])
    return Fraction(str(result.get_value(model.initial_states[0])))


@pytest.mark.parametrize("law", ["pmf(0.25, 0.25, 0.25, 0.25)", "pmf(0.3, 0.3)"])
def test_safety_chain_checked_by_storm_and_run(law: str, tmp_path: Any) -> None:
    """The controlled chain of a safety task's sensed controller (the worst case of
    ``G !(b & A)``, solved as the complement's maximum; and its best, where the
    chain's ``accept`` marks the bottom components kept safe for ever): Storm's
    ``P=? [F "accept"]`` is at least the controller's bound, and for the safety task
    equals Storm's own ``P=? [G !("reject" | "truncated")]`` on the same file (the
    runs never rejected; to the rounding of the file's decimals, whose rows need not
    sum to 1 exactly); a law that may never happen included.  ``mitld-lp run``
    serves the saved controller."""
    import json
    import subprocess
    import sys

    from mitld_lp.running.chain import write_chain

    model = Model.from_game(PUSHED, "G !(b & A) & G[0,3] !h",
                            events={"b": pmf([float(x) for x in law[4:-1].split(",")])},
                            sensors={"b": {"detect": 0.5}}, epsilon=1e-4)
    best = synthesize(model)
    path = write_chain(best, tmp_path / "best.drn")
    value = _storm(path, 'P=? [F "accept"]')
    assert Fraction(best.lower) <= value <= Fraction(best.upper)
    ends = [f'"{x}"' for x in ("reject", "truncated") if f" {x}" in path.read_text()]
    never_bad = _storm(path, f"P=? [G !({' | '.join(ends)})]")
    assert ends and abs(value - never_bad) < 1e-12  # the DRN's decimals round the rows
    assert 0 < value < 1
    worst = synthesize(model, objective="min")
    failing = _storm(write_chain(worst, tmp_path / "worst.drn"), 'P=? [F "accept"]')
    assert Fraction(worst.complement[0]) <= failing  # "accept" marks the failing runs
    saved = best.controller.save(tmp_path / "c.npz")
    lines = [{"state": "mid"}, {"state": "st", "reports": ["b"]}, {"state": "mid"}]
    done = subprocess.run([sys.executable, "-m", "mitld_lp", "run", str(saved)],
                          input="".join(json.dumps(x) + "\n" for x in lines),
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr
    replies = [json.loads(x) for x in done.stdout.splitlines()]
    best.controller.reset()
    from mitld_lp.controllers.observation import Observation

    expected = [best.controller.act(Observation("mid")),
                best.controller.act(Observation("st", reports={"b"})),
                best.controller.act(Observation("mid"))]
    assert [x["action"] for x in replies] == expected


def test_simulation_of_a_safety_controller_within_its_interval() -> None:
    """Rollouts of the obligation's sensed controller (hidden bus times and reports
    drawn, the task judged on the true events; a run kept safe to the horizon counts as
    a success, as for a fully observed safety task) agree with its certified value."""
    from mitld_lp.sensing.observe import simulate_sensed

    law = f"D[pmf({', '.join(map(str, PMF))})] b & "
    model = Model.from_game(STATION, law + "F(b & F[0,2] A) & G !h",
                            sensors={"b": {"detect": 0.5}})
    r = synthesize(model)
    sim = simulate_sensed(model, r.controller, runs=3000, seed=2, max_steps=40)
    sigma = math.sqrt(r.lower * (1 - r.lower) / sim.runs)
    assert abs(sim.estimate - r.lower) <= 4.5 * sigma and sim.kept > 0


def _random_world(rng: Any) -> ExplicitGame:
    """Three states (``s1`` at ``A``, ``s2`` at ``h``), one or two actions each, each
    to one or two random successors."""
    names = ["s0", "s1", "s2"]
    transitions: dict[str, dict[str, dict[str, float]]] = {}
    for s in names:
        transitions[s] = {}
        for a in ["x", "y"][:rng.choice([1, 2])]:
            to = rng.sample(names, rng.choice([1, 2]))
            p = rng.choice([0.25, 0.5, 0.75])
            transitions[s][a] = {to[0]: 1.0} if len(to) == 1 else {to[0]: p, to[1]: 1 - p}
    return ExplicitGame(initial="s0", transitions=transitions,
                        labels={"s1": {"A"}, "s2": {"h"}})


@pytest.mark.parametrize("seed", range(12))
def test_random_small_worlds_equal_expectimax(seed: int) -> None:
    """Random worlds, laws (some may never happen), sensors, task classes and
    objectives: the certified bracket holds the expectimax's value."""
    import random

    rng = random.Random(seed)
    world = _random_world(rng)
    masses = rng.choice([(0.5, 0.5), (0.25, 0.25, 0.5), (0.3, 0.3), (0.5,), (0.2, 0.3, 0.1)])
    detect = rng.choice([0.0, 0.5, 0.75])
    objective = rng.choice(["max", "min"])
    k, law = len(masses), f"D[pmf({', '.join(map(str, masses))})] b & "
    tasks: list[tuple[str, bool, Judge, int]] = [
        ("G !(b & A)", True, avoided(world, ["A"]), k),
        (f"F[0,{k + 2}] A & G[0,{k + 2}] !(b & A)", True,
         both(visited_by(world, "A", k + 2), avoided(world, ["A"])), k + 2),
        (law + "F(b & F[0,2] A)", False, caught(world, "A", 2), k + 2),
        (law + f"F(b & F[0,1] A) & G[0,{k + 2}] !h", False,
         both(caught(world, "A", 1), lambda trace, _: not any(s == "s2" for s in trace)),
         k + 2),
    ]
    spec, own_law, judge, horizon = tasks[seed % len(tasks)]
    model = Model.from_game(world, spec, events={"b": pmf(list(masses))} if own_law else None,
                            sensors={"b": {"detect": detect}}, epsilon=1e-4)
    r = synthesize(model, objective=objective)
    exact = expectimax(world, [(_frac(masses), Fraction(str(detect)))], judge, horizon,
                       sense=max if objective == "max" else min)
    _within(r, exact, width=r.sta.epsilon_achieved + 1e-7)


def expectimax_every_step(game: ExplicitGame, masses: Sequence[Fraction], detect: Fraction,
                          judge: Judge, horizon: int, *, false_alarm: Fraction = Fraction(0),
                          delay: int = 0, sense: Callable[..., Fraction] = max) -> Fraction:
    """:func:`expectimax` with a sensor that reports or not at *every* step (not only
    until its first report): with probability ``false_alarm`` before step ``K + delay``
    and ``detect`` from it on, each step independently; one event, ``masses`` its steps
    1, 2, ... (the rest never).  The alive scenarios are the event's step ``k`` (None:
    never) with the joint probability of the reports seen so far."""

    def report(k: int | None, s: int) -> Fraction:
        return detect if k is not None and s >= k + delay else false_alarm

    def best(trace: list[str], alive: list[tuple[int | None, Fraction]]) -> Fraction:
        t = len(trace) - 1
        if t == horizon:
            return sum((p * Fraction(judge(trace, ((k, None),))) for k, p in alive),
                       Fraction(0))
        values = []
        for action in game.actions(trace[-1]):
            v = Fraction(0)
            for nxt, ps in game.successors(trace[-1], action, frozenset()):
                for seen in (True, False):
                    g = [(k, p * Fraction(str(ps)) * (report(k, t + 1) if seen
                                                     else 1 - report(k, t + 1)))
                         for k, p in alive]
                    g = [(k, p) for k, p in g if p > 0]
                    if g:
                        v += best([*trace, nxt], g)
            values.append(v)
        return sense(values)

    start = [(k, mu) for k, mu in enumerate(masses, start=1)]
    never = 1 - sum(masses, Fraction(0))
    return best([game.initial], start + ([(None, never)] if never else []))


@pytest.mark.parametrize("detect, delay", [(0.5, 0), (0.9, 1)])
def test_every_step_reports_without_false_alarms_give_the_first_report_optimum(
        detect: float, delay: int) -> None:
    """With ``false_alarm = 0`` a sensor that reports at every step (independently, from
    ``K + delay`` on) gives the optimum of one that stops at its first report: after a
    report every hypothesis left is due, so the later ones tell nothing
    (docs/semantics.md, "False alarms").  The route's answer (first report) against the
    every-step expectimax, both objectives of ``G !(b & A)`` and the maximum of a
    deadline task (an obligation)."""
    d = Fraction(str(detect))
    sensors = {"b": {"detect": detect, "delay": delay}}
    model = Model.from_game(STATION, "G !(b & A)", events={"b": pmf(list(PMF))},
                            sensors=sensors)
    judge = avoided(STATION, ["A"])
    for objective, sense in (("max", max), ("min", min)):
        exact = expectimax_every_step(STATION, _frac(PMF), d, judge, 5, delay=delay,
                                      sense=sense)
        _within(synthesize(model, objective=objective), exact)
    law = f"D[pmf({', '.join(map(str, PMF))})] b & "
    bounded = Model.from_game(STATION, law + "F(b & F[0,2] A) & G[0,6] !h",
                              sensors=sensors)
    judge = both(caught(STATION, "A", 2), lambda trace, _: "ditch" not in trace)
    exact = expectimax_every_step(STATION, _frac(PMF), d, judge, 6, delay=delay)
    _within(synthesize(bounded), exact)
    # the per-step reports are not pure noise here: a false alarm changes the optimum
    noisy = expectimax_every_step(STATION, _frac(PMF), d, judge, 6, delay=delay,
                                  false_alarm=Fraction(1, 5))
    assert noisy < exact
