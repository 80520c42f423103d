"""A sensor that misses its event, a law known only within a band and a task with a
safety part (a safety task, an obligation, a co-safe task's minimum) with a constraint
or ``then`` (issue 43; :mod:`mitld_lp.routes.sensed_band_constrained`, its keeps).

Independent routes: an enumeration in exact arithmetic of the returned controller's
runs in STATION (tests/test_sensing_tasks.py) -- the bus's step, the camera's report
steps, the world's branches, the controller's draw after replaying each observation
history -- with nature choosing the hazard of every step among the band's two ends
after seeing the draw, the task and the constraint judged on the trace from the
formulas' meaning (no automaton, no information states, no end components; a stay is
the robot waiting where it stands for ever, judged on the world); Storm's robust check
of the exported interval chain; and the point-law answers at the band's ends, each an
upper bound of the worst case over the band."""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from test_sensing_tasks import PUSHED, STATION

from mitld_lp import Model, synthesize
from mitld_lp.distributions import from_table

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")

BAND = ("0.3", "0.5")
DETECT = "0.5"
EPSILON = 0.1  # the bus truncated at step 7: the controllers' tables stay small
#: the worlds where the robot can wait for ever (their only action keeps it there)
HAVENS = {"mid": "wait", "ditch": "stay"}


def _law(band: tuple[str, str] = BAND) -> Any:
    return from_table({"geometric": [float(band[0]), float(band[1])]}, "mu")


def safety_model() -> Model:
    """``G !(b & A)``: never at the station when the bus passes."""
    return Model.from_game(STATION, "G !(b & A)", events={"b": _law()},
                           sensors={"b": {"detect": float(DETECT)}}, epsilon=EPSILON)


# A judge of a trace: ``(t, world, bus step or None, worlds so far)`` -> True (holds
# whatever comes), False (fails whatever comes) or None (not decided yet)
Judge = Callable[[int, str, int | None, tuple[str, ...]], bool | None]


def runs(result: Any, game: Any, judge: Judge, pick: Callable[[list[Fraction]], Fraction],
         *, truncated: Fraction, waiting: Callable[[str, int | None, tuple[str, ...]],
                                                   Fraction]) -> Fraction:
    """The probability that ``judge`` says True under ``result``'s controller in
    ``game`` (:func:`enumerated`), the band :data:`BAND`, the camera :data:`DETECT`,
    the truncation point ``result``'s."""
    return enumerated(result.controller.plan, game, BAND, DETECT, judge, pick,
                      horizon=result.sta.clocks["b"].truncation, truncated=truncated,
                      waiting=waiting)


def enumerated(plan: Any, game: Any, band: tuple[str, str], detect: str, judge: Judge,
               pick: Callable[[list[Fraction]], Fraction], *, horizon: int | None = None,
               truncated: Fraction = Fraction(0),
               waiting: Callable[[str, int | None, tuple[str, ...]], Fraction] | None = None
               ) -> Fraction:
    """The probability that ``judge`` says True under the observation-based ``plan``
    (its mixed decision after each observation history) in ``game`` with the bus ``b``
    seen by a camera of ``detect``, nature picking the hazard of each step before the
    bus among ``band``'s ends by ``pick`` after seeing the robot's draw, in exact
    arithmetic; a run whose bus has not come by ``horizon`` (the truncation point) is
    worth ``truncated``; a run whose controller stays is worth ``waiting(world, bus,
    trace)`` (the robot waits there for ever; None: no stay expected)."""
    d, ends = Fraction(detect), tuple(Fraction(x) for x in band)
    memo: dict[tuple, Fraction] = {}

    def value(t: int, w: str, k: int | None, reported: bool, memory: Any,
              trace: tuple[str, ...]) -> Fraction:
        verdict = judge(t, w, k, trace)
        if verdict is not None:
            return Fraction(int(verdict))
        key = (t, w, k, reported, memory, trace)
        if key in memo:
            return memo[key]
        decision = plan.decision(w, memory)
        assert not decision.lost, "a stop with the task undecided: not expected"
        assert waiting is not None or not decision.stay, "a stay: not expected"
        stay = Fraction(decision.stay)
        out = stay * waiting(w, k, trace) if stay and waiting is not None else Fraction(0)
        weights = [Fraction(1)] if decision.weights is None else [
            Fraction(float(x)) for x in decision.weights]
        total = sum(weights)
        for action, x in zip(decision.actions, weights, strict=True):
            if x == 0:
                continue
            options = []
            for h in (ends if k is None else (None,)):
                v = Fraction(0)
                for k2, pe in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                    if pe == 0:
                        continue
                    if k2 is None and horizon is not None and t + 1 >= horizon:
                        v += pe * truncated  # past the truncation point
                        continue
                    told = ([(True, d), (False, 1 - d)] if k2 is not None and not reported
                            else [(reported, Fraction(1))])
                    for now, pr in told:
                        seen = frozenset({"b"}) if now and not reported else frozenset()
                        for nxt, pw in game.successors(w, action, frozenset()):
                            after, _ = plan.follow(memory, nxt, seen, action)
                            v += pe * pr * Fraction(str(pw)) * value(
                                t + 1, nxt, k2, now, after, trace + (nxt,))
                options.append(v)
            out += (1 - stay) * x / total * pick(options)
        memo[key] = out
        return out

    g0 = game.initial
    return value(0, g0, None, False, plan.start(g0), (g0,))


def _safe(t: int, w: str, k: int | None, trace: tuple[str, ...]) -> bool | None:
    """``G !(b & A)``: the bus passes once; it fails where the robot is at A then."""
    if k is None:
        return None
    return "A" not in STATION.propositions(trace[k])


def _early(limit: int) -> Judge:
    """``F[0,limit] A`` on the worlds so far."""
    def judge(t: int, w: str, k: int | None, trace: tuple[str, ...]) -> bool | None:
        if any("A" in STATION.propositions(x) for x in trace[:limit + 1]):
            return True
        return False if t >= limit else None
    return judge


def _waits_safely(w: str, k: int | None, trace: tuple[str, ...]) -> Fraction:
    # waiting for ever at mid or in the ditch: the bus passes where there is no A
    return Fraction(int(w in HAVENS))


@pytest.fixture(scope="module")
def safety() -> Any:
    return synthesize(safety_model(), constraints=["P(F[0,2] A) >= 0.3"])


def test_a_safety_task_with_a_constraint_is_the_worst_case_over_nature(safety) -> None:
    """The returned controller's worst case over nature, by the enumeration, is ``lower``
    (the runs past the truncation point counted lost, as ``lower`` counts them) and at
    most the task's true worst case; the constraint's worst case meets its bound and is
    the bound the answer gives."""
    r = safety
    assert r.route == "sensed-constrained" and r.status == "optimal" and r.bands
    assert r.controller is not None and r.part.chosen_at
    lost = runs(r, STATION, _safe, min, truncated=Fraction(0), waiting=_waits_safely)
    won = runs(r, STATION, _safe, min, truncated=Fraction(1), waiting=_waits_safely)
    assert abs(lost - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert Fraction(r.lower) <= won and r.lower <= r.upper
    (c,) = r.constraints
    assert c.holds
    worst = runs(r, STATION, _early(2), min, truncated=Fraction(0),
                 waiting=lambda w, k, trace: Fraction(0))
    assert worst >= Fraction(3, 10)
    assert abs(worst - Fraction(c.bounds[0])) <= Fraction(1, 10**9)


def test_the_band_s_answer_is_below_the_point_laws_at_its_ends(safety) -> None:
    """Nature may play either end of the band for ever: no controller's worst case is
    above the best a controller does at an end (the point-law route's upper bound), and
    the band's ``upper`` is not above those either."""
    for end in BAND:
        point = synthesize(Model.from_game(
            STATION, "G !(b & A)", events={"b": from_table({"geometric": float(end)}, "mu")},
            sensors={"b": {"detect": float(DETECT)}}, epsilon=EPSILON),
            constraints=["P(F[0,2] A) >= 0.3"])
        assert point.route == "sensed-constrained" and not point.bands
        assert safety.lower <= point.upper + 1e-9
        assert safety.upper <= point.upper + 1e-9


@needs_storm
def test_storm_on_the_kept_interval_chain(safety, tmp_path: Path) -> None:
    """Storm's robust check of the exported file: ``Pmin [F "accept"]`` (nature
    minimising) is ``lower``; ``Pmin [F "c1"]`` the constraint's worst case."""
    import stormpy
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import sensed_band_claim, write_sensed_band_chain

    path = write_sensed_band_chain(safety, tmp_path / "kept.drn")
    assert abs(storm_worst(path) - safety.lower) <= 1e-9
    assert sensed_band_claim(safety)[0] == safety.lower
    chain = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    got = stormpy.model_checking(
        chain, stormpy.parse_properties('Pmin=? [F "c1"]')[0], environment=env,
        uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.MINIMIZE)
    (c,) = safety.constraints
    assert abs(float(got.get_value(chain.initial_states[0])) - c.bounds[0]) <= 1e-9


def _caught(t: int, w: str, k: int | None, trace: tuple[str, ...]) -> bool | None:
    """``F(b & F[0,2] A)`` in PUSHED: at A within two steps of the bus."""
    if k is not None and any("A" in PUSHED.propositions(x) for x in trace[k:k + 3]):
        return True
    if k is not None and t >= k + 2:
        return False
    return None


def _fell_by(limit: int, *, with_task: bool) -> Judge:
    """``F[0,limit] h``; ``with_task``: a run left as not fallen only once the task is
    decided too (as the chain of the task and the formula runs on, where a run past the
    truncation point counts against the constraint)."""
    def judge(t: int, w: str, k: int | None, trace: tuple[str, ...]) -> bool | None:
        if any("h" in PUSHED.propositions(x) for x in trace[:limit + 1]):
            return True
        done = t >= limit and (not with_task or _caught(t, w, k, trace) is not None)
        return False if done else None
    return judge


def test_a_minimum_with_a_constraint_reads_the_complement_back(tmp_path: Path) -> None:
    """The least probability of catching the bus in PUSHED, falling into the ditch by
    step 4 at most 0.35 under every law of the band: ``upper`` is the returned
    controller's worst case (nature making the bus as easy to catch as it can), at least
    its true worst case by the enumeration (a run past the truncation point counted
    caught, as the complement's lower model counts it, or not: between them); the
    constraint's worst case, nature pushing to the ditch, meets the bound; Storm's check
    of the exported file (the complement's chain) gives ``1 - upper``."""
    model = Model.from_game(PUSHED, "D[mu] b & F(b & F[0,2] A)", objective="min",
                            distributions={"mu": _law()},
                            sensors={"b": {"detect": float(DETECT)}}, epsilon=EPSILON)
    r = synthesize(model, constraints=["P(F[0,4] h) <= 0.35"])
    assert r.route == "sensed-constrained" and r.status == "optimal" and r.bands
    assert r.complemented and r.complement is not None
    assert abs(r.complement[0] - (1 - r.upper)) <= 1e-12
    # waiting for ever in the ditch: the bus is not caught any more
    ditch = lambda w, k, trace: Fraction(0)  # noqa: E731
    caught = runs(r, PUSHED, _caught, max, truncated=Fraction(1), waiting=ditch)
    never = runs(r, PUSHED, _caught, max, truncated=Fraction(0), waiting=ditch)
    assert never <= Fraction(r.upper) and abs(caught - Fraction(r.upper)) <= Fraction(1, 10**9)
    assert r.lower <= r.upper
    (c,) = r.constraints
    assert c.holds
    fallen = lambda w, k, trace: Fraction(int(w == "ditch"))  # noqa: E731
    fell = runs(r, PUSHED, _fell_by(4, with_task=False), max, truncated=Fraction(1),
                waiting=fallen)
    counted = runs(r, PUSHED, _fell_by(4, with_task=True), max, truncated=Fraction(1),
                   waiting=fallen)
    assert fell <= counted <= Fraction(35, 100)
    assert abs(counted - Fraction(c.bounds[1])) <= Fraction(1, 10**9)
    if importlib.util.find_spec("stormpy") is not None:
        from test_band_chain import storm_worst

        from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

        path = write_sensed_band_chain(r, tmp_path / "min.drn")
        assert abs(storm_worst(path) - (1 - r.upper)) <= 1e-9


def test_a_law_that_does_not_give_every_outcome_of_the_band_is_not_trusted() -> None:
    """The end components a keep rests on are those of the candidate's law: a law that
    rules out an outcome some law of the band gives (a geometric band reaching 1, at its
    high end: no "not yet") does not cover the band; its middle and low end do."""
    from mitld_lp.automata.sta import EventClock
    from mitld_lp.routes.sensed_band import end_laws
    from mitld_lp.routes.sensed_band_constrained import covers

    band = _law(("0.3", "1.0"))

    def at(law: Any) -> Any:
        return SimpleNamespace(sta=SimpleNamespace(clocks={"b": EventClock("b", law, 0, 9)}))

    ends = dict(end_laws({"b": band}))
    assert covers(at(band)) and covers(at(ends["low ends"]["b"]))
    assert not covers(at(ends["high ends"]["b"]))
    point = from_table({"geometric": 0.5}, "mu")
    assert covers(at(point))  # no band: nothing to cover


def _corners(rows: list[list[dict[int, float]]], accept: set[int]) -> Any:
    """An interval chain whose every state's choices are nature's corners (point
    intervals), ``rows[s]`` the distributions of state ``s``'s choices."""
    import numpy as np
    import scipy.sparse as sp

    from mitld_lp.running.band_chain import BandChain

    flat = [r for here in rows for r in here]
    n = len(rows)
    matrix = sp.csr_array(([p for r in flat for p in r.values()],
                           ([i for i, r in enumerate(flat) for _ in r],
                            [j for r in flat for j in r])), shape=(len(flat), n))
    groups = np.cumsum([0] + [len(h) for h in rows])
    labels = tuple(frozenset({"accept"} if s in accept else ()) for s in range(n))
    return BandChain(matrix, matrix.data.copy(), groups, tuple(f"c{i}" for i in range(len(flat))),
                     labels, tuple(str(s) for s in range(n)), np.full(n, -1))


@pytest.mark.parametrize(("rows", "expected"), [
    # nature may loop for ever (the first corner leads to the target): never reached
    ([[{1: 1.0}, {0: 1.0}], [{1: 1.0}]], Fraction(0)),
    # a loop left with probability 1e-6 each round: reached for sure, at last (value
    # iteration from below is still at 0.63 after a million rounds)
    ([[{0: 1 - 1e-6, 1: 1e-6}], [{1: 1.0}]], Fraction(1)),
    # the same beside a state where nature may loop for ever
    ([[{0: 1 - 1e-6, 1: 1e-6}], [{1: 1.0}], [{2: 1.0}, {1: 1.0}]], Fraction(1)),
    # x0 = min(1/2 + x1/2, 3/10), x1 = 9/10 x0: the second corner, 3/10
    ([[{1: 0.5, 2: 0.5}, {1: 0.3, 3: 0.7}], [{1: 1.0}], [{0: 0.9, 3: 0.1}], [{3: 1.0}]],
     Fraction(3, 10)),
])
def test_nature_s_least_reaching_probability_by_hand(rows, expected) -> None:
    """:func:`~mitld_lp.running.sensed_band_chain.reach_min` on small interval chains
    whose values are worked out by hand: a lower bound within 1e-8 of them."""
    from mitld_lp.running.sensed_band_chain import reach_min

    chain = _corners(rows, {1})
    got = Fraction(reach_min(chain, chain.accepting()))
    assert expected - Fraction(1, 10**8) <= got <= expected


@needs_storm
def test_the_tree_of_the_kept_controller_keeps_its_worst_case(safety, tmp_path: Path) -> None:
    """``export --tree``: the tree controller (its leaves the controller's mixed
    decisions, stays and keeps included) has the controller's worst case over the band:
    Storm's robust check of the tree controller's interval chain gives ``lower``."""
    from test_band_chain import storm_worst

    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain
    from mitld_lp.running.tree import tree_controller, tree_of

    tree = tree_of(safety)
    by_tree = tree_controller(safety, tree)
    path = write_sensed_band_chain(safety, tmp_path / "tree.drn", controller=by_tree)
    assert abs(storm_worst(path) - safety.lower) <= 1e-9
