"""A sensor with false alarms, a law known only within a band whose laws surely happen,
and constraints, ``then`` or the trade-off curve (issue 43; the sensed band constrained
route, its candidates the sensed constrained solves with false alarms at the band's
laws, each judged on its interval chain).

Independent routes:

* an enumeration in exact arithmetic of the returned randomised controller's runs
  (written here, after tests/test_false_alarms_band.py's worst case): the step the
  event comes, the sensor's report or silence at *every* step (``false_alarm`` before
  the event, ``detect`` from its step on), the world's branches, the controller's draw
  (its mixed decision after each observation, through its own memory), and nature
  choosing the hazard of each step among the band's two ends after seeing the draw, by
  ``min`` or ``max`` (or one end at every step: a constant law of the band); the task
  and the constraint judged on the run from the formulas' meaning (no automaton, no
  information states, no chain);
* an occupancy LP over the robot's observation histories (world path and every step's
  report) at a constant law of the band, solved by scipy: the constrained optimum at
  that law, which no controller meeting the constraint under every law beats;
* Storm's robust check of the exported interval chain (the task, the constraint, the
  expected steps);
* for nature's least reaching probability on a chain that leaves a loop with a tiny
  probability, values worked out by hand.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mitld_lp import ExplicitGame, Model, load_model, synthesize
from mitld_lp.distributions import from_table
from mitld_lp.sensing import Sensor

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy")

# "go" reaches A with 3/4, "hold" with 1/4; from A a round of three steps back; the
# task: the event at a step k <= 3 and A at a step in [k, k + 1] (decided by step 4)
GAME = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 0.75, "mid": 0.25}, "hold": {"sa": 0.25, "mid": 0.75}},
    "sa": {"back": {"trap": 1.0}}, "trap": {"back": {"mid": 1.0}}})
#: the same with "wait" for "hold" (tests/test_sensed_band.py's): waiting for a report
#: before going pays, so the reports steer the controller
WAITING = ExplicitGame(initial="mid", labels={"sa": {"A"}}, transitions={
    "mid": {"go": {"sa": 0.75, "mid": 0.25}, "wait": {"mid": 1.0}},
    "sa": {"back": {"trap": 1.0}}, "trap": {"back": {"mid": 1.0}}})
SPEC = "D[mu] b & F[0,3] (b & F[0,1] A)"
HORIZON = 4
BAND, DETECT, ALARM = ("0.3", "0.6"), "0.6", "0.2"
CONSTRAINT = "P(F[0,2] A) <= 0.5"  # A early: decided by step 2

#: a judge of a run at step ``t`` in world ``w`` with the event at step ``k`` (None:
#: not yet): True (holds whatever comes), False (fails whatever comes), None (open)
Judge = Callable[[int, str, int | None], bool | None]


def model(alarm: str = ALARM, band: tuple[str, str] = BAND, game: ExplicitGame = GAME,
          **kw: Any) -> Model:
    law = from_table({"geometric": [float(band[0]), float(band[1])]}, "mu")
    return Model.from_game(game, SPEC, distributions={"mu": law},
                           sensors={"b": Sensor(float(DETECT), false_alarm=float(alarm))},
                           **kw)


def task(t: int, w: str, k: int | None) -> bool | None:
    if k is not None and k <= t <= k + 1 and w == "sa":  # A
        return True
    return False if (k is None and t >= 3) or (k is not None and t >= k + 1) else None


def early(t: int, w: str, k: int | None) -> bool | None:
    if t <= 2 and w == "sa":  # A
        return True
    return False if t >= 2 else None


def by_nature(plan: Any, judge: Judge, pick: Callable[[list[Fraction]], Fraction], *,
              game: ExplicitGame = GAME, band: tuple[str, str] = BAND,
              alarm: str = ALARM, truncation: int | None = None,
              truncated: Fraction = Fraction(0)) -> Fraction:
    """The probability that ``judge`` says True under the observation-based ``plan``
    (its mixed decision after each observation: world state and that step's report) in
    ``game``, nature picking the hazard of each step before the event among ``band``'s
    ends by ``pick`` after seeing the robot's draw, the sensor reporting at every step
    (``alarm`` before the event, :data:`DETECT` from its step on), in exact
    arithmetic; a run whose event has not come by step ``truncation`` (the truncation
    point) is worth ``truncated``."""
    ends = tuple(Fraction(x) for x in band)
    detect, false_alarm = Fraction(DETECT), Fraction(alarm)
    memo: dict[tuple[Any, ...], Fraction] = {}

    def value(t: int, w: str, k: int | None, memory: Any) -> Fraction:
        verdict = judge(t, w, k)
        if verdict is not None:
            return Fraction(int(verdict))
        key = (t, w, k, memory)
        if key in memo:
            return memo[key]
        d = plan.decision(w, memory)
        assert not d.lost and not d.stay, "a stop or a stay with the run open: not expected"
        if d.weights is None:
            drawn = [(d.actions[0] if d.actions else plan.fallback(w), Fraction(1))]
        else:
            weights = [Fraction(float(x)) for x in d.weights]
            drawn = [(a, x / sum(weights)) for a, x in zip(d.actions, weights, strict=True)
                     if x > 0]
        out = Fraction(0)
        for action, p_action in drawn:
            options = []
            for h in (ends if k is None else (None,)):
                v = Fraction(0)
                for k2, p_event in ([(t + 1, h), (None, 1 - h)] if k is None else [(k, 1)]):
                    if k2 is None and truncation is not None and t + 1 >= truncation:
                        v += p_event * truncated  # past the truncation point
                        continue
                    q = detect if k2 is not None else false_alarm  # this step's report
                    for told, p_told in ((True, q), (False, 1 - q)):
                        seen = frozenset({"b"}) if told else frozenset()
                        for w2, p_world in game.successors(w, action, frozenset()):
                            after, _ = plan.follow(memory, w2, seen, action)
                            v += p_event * p_told * Fraction(str(p_world)) * value(
                                t + 1, w2, k2, after)
                options.append(v)
            out += p_action * pick(options)
        memo[key] = out
        return out

    return value(0, game.initial, None, plan.start(game.initial))


def history_lp(hazard: str, bound: float | None, alarm: str = ALARM,
               game: ExplicitGame = GAME) -> float:
    """The best probability of the task at the constant law ``geometric(hazard)`` over
    policies of the robot's observation histories in ``game`` (its world path and the
    report or silence of every step) with ``P(F[0,2] A) <= bound`` (None: no constraint): an
    occupancy LP over that tree of histories, solved by scipy."""
    from scipy.optimize import linprog

    h, d, f = float(hazard), float(DETECT), float(alarm)
    prior: dict[int | None, float] = {k: h * (1 - h) ** (k - 1) for k in (1, 2, 3)}
    prior[None] = (1 - h) ** 3  # later than step 3: the task fails

    def weights(reports: tuple[bool, ...]) -> dict[int | None, float]:
        out = {}
        for k, p in prior.items():
            for j, seen in enumerate(reports, start=1):
                q = d if k is not None and j >= k else f
                p *= q if seen else 1 - q
            out[k] = p
        return out

    def won(k: int | None, path: tuple[str, ...]) -> bool:
        return k is not None and any(path[s] == "sa" for s in (k, k + 1))

    index = {(("mid",), ()): 0}
    order = list(index)
    rows: list[int] = []
    cols: list[int] = []
    vals: list[float] = []
    gain: list[float] = []
    risk: list[float] = []
    head = 0
    while head < len(order):
        path, reports = order[head]
        head += 1
        here = weights(reports)
        for a in sorted(game.actions(path[-1])):
            j = len(gain)
            rows.append(index[(path, reports)])
            cols.append(j)
            vals.append(1.0)
            g = r = 0.0
            for w2, pw in game.successors(path[-1], a, frozenset()):
                path2 = (*path, w2)
                if len(path2) - 1 == HORIZON:  # decided: the task by the posterior
                    g += pw * sum(p for k, p in here.items() if won(k, path2)) / sum(
                        here.values())
                    r += pw * ("sa" in path2[:3])  # A by step 2
                    continue
                for seen in (True, False):
                    p = pw * sum(weights((*reports, seen)).values()) / sum(here.values())
                    node = (path2, (*reports, seen))
                    if node not in index:
                        index[node] = len(order)
                        order.append(node)
                    rows.append(index[node])
                    cols.append(j)
                    vals.append(-p)
            gain.append(g)
            risk.append(r)
    a_eq = np.zeros((len(order), len(gain)))
    np.add.at(a_eq, (rows, cols), vals)
    b_eq = np.zeros(len(order))
    b_eq[0] = 1.0
    ub = {} if bound is None else {"A_ub": np.array([risk]), "b_ub": [bound]}
    out = linprog(-np.array(gain), A_eq=a_eq, b_eq=b_eq, bounds=(0, None), method="highs",
                  **ub)
    assert out.status == 0, out.message
    return float(-out.fun)


@pytest.fixture(scope="module")
def constrained() -> Any:
    return synthesize(model(), constraints=[CONSTRAINT])


def test_the_constraint_holds_under_every_law_and_lower_is_the_worst_case(constrained
                                                                         ) -> None:
    """The returned controller's constraint, nature making A early as likely as it can,
    meets its bound and is the bound the answer gives; it holds at each constant law of
    the band's ends too; the task's worst case over nature is ``lower``; ``upper`` is at
    least that and at most the constrained optimum at either end law (nature may play
    it at every step: the history LP)."""
    r = constrained
    assert r.route == "sensed-constrained" and r.bands and str(r.status) == "optimal"
    assert r.controller is not None and r.controller.randomised
    plan = r.controller.plan
    (v,) = r.constraints
    assert v.holds
    worst_early = by_nature(plan, early, max)
    assert worst_early <= Fraction(1, 2)
    assert abs(worst_early - Fraction(v.bounds[1])) <= Fraction(1, 10**9)
    for end in (0, 1):  # nature at one end at every step
        assert by_nature(plan, early, lambda o, e=end: o[min(e, len(o) - 1)]) <= Fraction(1, 2)
    worst = by_nature(plan, task, min)
    assert abs(worst - Fraction(r.lower)) <= Fraction(1, 10**9)
    assert Fraction(r.upper) >= worst
    at_ends = [history_lp(h, 0.5) for h in BAND]
    assert r.upper <= min(at_ends) + 1e-6
    # the false alarms are read: without them the optimum at the low end is higher
    assert history_lp(BAND[0], 0.5, alarm="0") > at_ends[0] + 1e-3


def test_the_false_alarms_change_the_answer(constrained) -> None:
    """The same problem with a camera without false alarms (the sensed band constrained
    route as before) is worth more: with them a report no longer means the event came,
    and the controller reads every step's."""
    quiet = synthesize(model(alarm="0"), constraints=[CONSTRAINT])
    r = constrained
    assert quiet.route == r.route == "sensed-constrained"
    assert r.lower < quiet.lower - 1e-4 and r.upper < quiet.upper - 1e-4


@needs_storm
def test_storm_on_the_exported_interval_chain(constrained, tmp_path: Path) -> None:
    """Storm's robust check of the exported file: ``Pmin [F "accept"]`` (uncertainty
    MINIMIZE) is ``lower``, ``Pmax [F "c1"]`` (MAXIMIZE) the constraint's worst case."""
    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    r = constrained
    path = write_sensed_band_chain(r, tmp_path / "c.drn")
    assert abs(_storm(path, 'Pmin=? [F "accept"]', "MINIMIZE") - r.lower) <= 1e-9
    (v,) = r.constraints
    assert abs(_storm(path, 'Pmax=? [F "c1"]', "MAXIMIZE") - v.bounds[1]) <= 1e-8


def _storm(path: Path, prop: str, mode: str) -> float:
    """Storm's value of ``prop`` on the interval model at ``path``, nature resolving the
    uncertainty by ``mode``."""
    import stormpy

    chain = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    got = stormpy.model_checking(
        chain, stormpy.parse_properties(prop)[0], environment=env,
        uncertainty_resolution_mode=getattr(stormpy.UncertaintyResolutionMode, mode))
    return float(got.get_value(chain.initial_states[0]))


@needs_storm
def test_then_min_steps_its_worst_steps_are_storm_s(tmp_path: Path) -> None:
    """``then min-steps`` in :data:`WAITING` with the band ``[0.1, 0.9]`` (the reports
    steer the controller: an uninformative sensor's reports would lower its worst case):
    the returned controller's task worst case is ``lower`` (the enumeration); its
    expected steps at the worst law (nature maximising them), the answer's
    ``secondary``, are Storm's robust ``Rmax`` of the reward ``steps`` on the exported
    interval chain; ``upper`` at most the unconstrained optimum at either end law (the
    history LP)."""
    from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

    band = ("0.1", "0.9")
    r = synthesize(model(band=band, game=WAITING), then="min-steps")
    assert r.route == "sensed-constrained" and r.bands and r.controller is not None
    plan = r.controller.plan
    worst = by_nature(plan, task, min, game=WAITING, band=band)
    assert abs(worst - Fraction(r.lower)) <= Fraction(1, 10**9)
    noise = by_nature(plan, task, min, game=WAITING, band=band, alarm=DETECT)
    assert noise < worst - Fraction(1, 100)  # the reports are read
    assert r.upper <= min(history_lp(h, None, game=WAITING) for h in band) + 1e-6
    path = write_sensed_band_chain(r, tmp_path / "then.drn")
    steps = _storm(path, 'R{"steps"}max=? [F "done"]', "MAXIMIZE")
    assert 0 < r.secondary < float("inf") and abs(steps - r.secondary) <= 1e-8
    assert abs(_storm(path, 'Pmin=? [F "accept"]', "MINIMIZE") - r.lower) <= 1e-9


def test_pareto_with_false_alarms_and_a_band() -> None:
    """The trade-off curve against ``P(F[0,2] A)``: each point is this route's answer,
    no better than the constrained optimum at either end law with its bound (the
    history LP), a looser bound worth at least a tighter one."""
    from mitld_lp.tradeoff import pareto

    points = pareto(model(), "P(F[0,2] A)", points=3)
    solved = [p for p in points if p.status == "optimal"]
    assert len(points) == 3 and solved
    for p in solved:
        assert -1e-9 <= p.lower <= p.upper + 1e-9
        assert p.lower <= min(history_lp(h, p.bound) for h in BAND) + 1e-7
    lows = [p.lower for p in solved]
    assert all(a <= b + 1e-9 for a, b in zip(lows, lows[1:], strict=False))


def test_a_minimum_with_a_constraint_reads_the_complement_back() -> None:
    """``objective = "min"`` with ``P(F[0,2] A) >= 0.4``: ``upper`` is the returned
    controller's worst case (nature making the task as likely as it can, the
    enumeration with ``max``), the constraint's worst case (nature against it) meets
    its bound."""
    r = synthesize(model(objective="min"), constraints=["P(F[0,2] A) >= 0.4"])
    assert r.route == "sensed-constrained" and r.bands and r.complemented
    assert r.controller is not None
    (v,) = r.constraints
    assert v.holds
    plan = r.controller.plan
    assert abs(by_nature(plan, task, max) - Fraction(r.upper)) <= Fraction(1, 10**9)
    worst_early = by_nature(plan, early, min)
    assert worst_early >= Fraction(2, 5)
    assert abs(worst_early - Fraction(v.bounds[0])) <= Fraction(1, 10**9)
    assert r.lower <= r.upper


def safe(t: int, w: str, k: int | None) -> bool | None:
    """``G !(b & A)``: the event passes once, at step ``k``; it fails where the robot is
    at A then, else it holds for ever."""
    return w != "sa" if k == t else None


def test_a_safety_task_kept_under_every_law(tmp_path: Path) -> None:
    """``G !(b & A)`` (not at A when the event passes) in :data:`WAITING` with
    ``P(F[0,2] A) >= 0.3``: a safety part, kept where the robot has seen enough (a keep
    ends the chain's run with the task accepted where the true run is persistent).  The
    returned controller's worst case over nature is ``lower`` (the runs past the
    truncation point counted lost, as ``lower`` counts them) and, those runs counted
    won, its ``truncated_won``; the constraint's worst case (nature against it) meets
    its bound and is the bound the answer gives; Storm on the exported chain gives
    ``lower``."""
    law = from_table({"geometric": [float(BAND[0]), float(BAND[1])]}, "mu")
    m = Model.from_game(WAITING, "G !(b & A)", events={"b": law}, epsilon=0.3,
                        sensors={"b": Sensor(float(DETECT), false_alarm=float(ALARM))})
    r = synthesize(m, constraints=["P(F[0,2] A) >= 0.3"])
    assert r.route == "sensed-constrained" and r.bands and str(r.status) == "optimal"
    assert r.controller is not None
    plan, cut = r.controller.plan, r.sta.clocks["b"].truncation
    lost = by_nature(plan, safe, min, game=WAITING, truncation=cut)
    assert abs(lost - Fraction(r.lower)) <= Fraction(1, 10**9)
    won = by_nature(plan, safe, min, game=WAITING, truncation=cut, truncated=Fraction(1))
    assert abs(won - Fraction(r.part.worst.truncated_won)) <= Fraction(1, 10**9)
    assert lost < won and Fraction(r.upper) >= lost
    (v,) = r.constraints
    assert v.holds
    reach = by_nature(plan, early, min, game=WAITING, truncation=cut)
    assert reach >= Fraction(3, 10) and abs(reach - Fraction(v.bounds[0])) <= Fraction(
        1, 10**9)
    if importlib.util.find_spec("stormpy") is not None:
        from mitld_lp.running.sensed_band_chain import write_sensed_band_chain

        path = write_sensed_band_chain(r, tmp_path / "kept.drn")
        assert abs(_storm(path, 'Pmin=? [F "accept"]', "MINIMIZE") - r.lower) <= 1e-9


def test_a_band_that_may_never_happen_is_bracketed_not_refused() -> None:
    """A band with false alarms whose law may never happen: its worst case is bracketed
    by this route (tests/test_false_alarms_never_band.py), so not refused, nor one that
    surely happens; its best law (``worst = False``) is refused, naming the routes that
    bracket it."""
    from types import SimpleNamespace

    from mitld_lp.distributions import pmf
    from mitld_lp.routes.sensed_band_constrained import alarm_band_refusals

    def with_law(law: Any) -> Any:
        return SimpleNamespace(sensors={"b": Sensor(0.6, false_alarm=0.2)},
                               distributions={"b": law})

    assert alarm_band_refusals(with_law(pmf([0.3, 0.3])), worst=True) == []
    assert alarm_band_refusals(with_law(pmf([0.3, 0.7])), worst=True) == []
    (said,) = alarm_band_refusals(with_law(pmf([0.3, 0.3])))
    assert "never happens with probability 0.4" in said
    assert "with constraints or then its worst or best law" in said


def test_a_run_left_in_a_loop_for_ever_almost_never_reaches_the_target_surely() -> None:
    """A controller that waits for ever on a sensor with false alarms leaves its loop
    with a tiny probability (an interior-point solution's residue): 40 states in a row,
    each left for the next with probability 1e-9 a step (nature choosing that or 2e-9),
    the last into the target, and a side state nature may keep out of it for ever.
    Every run from the row reaches the target, by the graph alone (value 1, where
    value iteration from below would need billions of rounds); the side state's value
    is 0, and a state that nature may send there with 1/2 is worth 1/2."""
    import scipy.sparse as sp

    from mitld_lp.running.band_chain import BandChain
    from mitld_lp.running.sensed_band_chain import reach_min

    n = 40  # the row 0..n-1, the target n, the side state n + 1, the fork n + 2
    rows: list[list[dict[int, float]]] = [
        [{i: 1 - e, i + 1: e} for e in (1e-9, 2e-9)] for i in range(n)]
    rows += [[{n: 1.0}], [{n + 1: 1.0}, {n: 1.0}], [{0: 0.5, n + 1: 0.5}]]
    target = np.zeros(len(rows), dtype=bool)
    target[n] = True

    def at(start: int) -> float:  # the chain with ``start`` as its state 0
        order = [start, *(s for s in range(len(rows)) if s != start)]
        perm = np.argsort(order)  # old state -> new
        grouped = [[{int(perm[j]): p for j, p in r.items()} for r in rows[s]]
                   for s in order]
        f = [r for here in grouped for r in here]
        m = sp.csr_array(([p for r in f for p in r.values()],
                          ([i for i, r in enumerate(f) for _ in r],
                           [j for r in f for j in r])), shape=(len(f), len(order)))
        g = np.cumsum([0] + [len(h) for h in grouped])
        chain = BandChain(m, m.data.copy(), g, tuple(str(i) for i in range(len(f))),
                          tuple(frozenset() for _ in order), tuple(map(str, order)),
                          np.full(len(order), -1))
        return reach_min(chain, target[order])

    assert at(0) == 1.0 and at(n - 1) == 1.0
    assert at(n + 1) == 0.0
    assert 0.5 - 1e-12 <= at(n + 2) <= 0.5


@needs_storm
def test_export_chain_from_a_model_file_carries_the_steps(tmp_path: Path, capsys) -> None:
    """``mitld-lp export --chain`` of a model file with a band, false alarms and a bound
    on the expected steps: Storm's robust check of the file gives ``lower`` for the task,
    at least 0.1 for the reach constraint (nature against it), and for the reward
    ``steps`` (nature maximising) the bound's worst case the answer gives, within 5."""
    import json

    from mitld_lp.cli import main

    path = tmp_path / "fa_band.toml"
    path.write_text('name = "fa_band"\nspec = "D[mu] b & F(b & F[0,2] A)"\n'
                    'constraints = ["P(F A) >= 0.1", "E(steps) <= 5"]\n'
                    "[grid]\nsize = [3, 1]\nstart = [0, 0]\n[regions]\nA = [[2, 0]]\n"
                    "[distributions]\nmu = { geometric = [0.3, 0.5] }\n"
                    "[sensors]\nb = { detect = 0.5, false_alarm = 0.1 }\n")
    out = tmp_path / "fa.drn"
    code = main(["export", str(path), "--epsilon", "0.3", "--chain", str(out), "--json"])
    said = json.loads(capsys.readouterr().out)
    assert code == (0 if said["certified"] else 3) and said["chain_accept"] == said["lower"]
    assert abs(_storm(out, 'Pmin=? [F "accept"]', "MINIMIZE") - said["lower"]) <= 1e-9
    assert _storm(out, 'Pmin=? [F "c1"]', "MINIMIZE") >= 0.1 - 1e-12
    r = synthesize(load_model(path), epsilon=0.3)
    steps = r.constraints[1]
    assert steps.holds and steps.bounds[1] <= 5
    worst = _storm(out, 'R{"steps"}max=? [F "done"]', "MAXIMIZE")
    assert abs(worst - steps.bounds[1]) <= 1e-8
