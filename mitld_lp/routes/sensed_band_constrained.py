"""Constraints or ``then`` with sensors that miss their events and a law known only
within a band: a randomised observation-based controller whose every constraint holds
under every law of the band, with a sound bracket on its task value's worst case.

Candidates: the ``sensed-constrained`` route's controller (:mod:`mitld_lp.routes.
sensed_constrained`, its information-state LP) at the band's laws that
:func:`mitld_lp.routes.sensed_band.end_laws` names (the middle law, every band at its
low end, at its high end); where a candidate's constraint fails under some law, that law's
LP again with the constraint's bound tightened by what the band added, an infeasible
LP's margins halved back (:data:`ROUNDS` rounds, :func:`_tighten`).

A sensor with false alarms (under a band whose laws surely happen; one that may never
happen is bracketed, below) changes no step: each candidate is
the ``sensed-constrained`` solve with false alarms at its law (its information states
keeping each hypothesis's count of reports), and its interval chain draws the report or
silence of every step (``false_alarm`` before the event's report is due, ``detect``
from then on: given the true event times, the same under every law of the band, so the
keeps below rest on the same argument as without false alarms).

Each candidate is judged on its interval chain (:mod:`mitld_lp.running.
sensed_band_chain`: the truth and the controller's memory, the joint automaton of the
task and the constraints' formulas, nature's corners as choices, nature seeing the
robot's draw): the task's worst case from below (``lower``), each ``P(.) <= x`` and
``E(.) <= x`` constraint's worst case from above (nature maximising, its strategy's
value proven an upper bound by a super-solution, :func:`~mitld_lp.running.
sensed_band_chain.nature_max`), each ``P(.) >= x`` one's from below.  A candidate whose
constraint's worst case misses its bound is discarded; the best survivor by its task's
worst case is returned.  If none survives, the status is ``failed``, no controller is
returned and no constraint is said to hold (a policy meeting a constraint at some laws
only is never returned as meeting it); it is ``infeasible`` where a probability
constraint's formula alone, seeing every event, has its robust optimum over the band
beyond the bound (:func:`mitld_lp.routes.robust_constrained.alone_bounds`: a robot that
sees more does no worse), and a ``failed`` answer gives those optima.

``upper``: the least of the candidates' upper bounds at their laws, each from the LP with
the problem's own bounds (a policy meeting the constraints under every law meets them at
that one, and its worst case is at most its value there); a problem infeasible at one of
those laws is infeasible under the band, and said so.  The answer is certified when
``upper`` less the candidate's worst case with truncated runs counted won is within the
precision (the rest is the truncation's, reported apart) and every check passed;
otherwise the check ``worst case over the band`` says the gap, both ends sound.

``then`` (``min-steps``/``min-cost``): each candidate is that law's lexicographic LP's
policy; the returned one's expected steps (and cost) at the worst law of the band
(nature maximising them), proven from above, are its ``steps`` (and ``secondary``).
Without ``then`` too, ``steps`` is the returned controller's worst case over the band,
not its value at the law it was solved at.

A task with a safety part (safety, obligation; a co-safe task's minimum): a candidate's
*keep* (:mod:`mitld_lp.routes.sensed_kept`) is a stay in a keep state, which its chain
ends with the task accepted exactly when the true run's hypothesis is persistent
(:meth:`mitld_lp.running.sensed_joint.JointEnds.stayed`); where the controller stays
elsewhere, the run ends with its verdicts, an undecided component not satisfied.  Both
rest on the end components of the candidate's information states, built at its law:
every run of the chain must be a run that law allows.  That holds when at every clock
the law gives each outcome of a step (the event, no event) that some law of the band
gives -- its hazard positive where the band's greatest is, below 1 where the band's
least is (:func:`covers`); persistence and the end components are then the same under
every law of the band (the band's runs are among the law's, and a hypothesis persistent
in every state of an end component stays so on each of them).  A candidate that stays
or keeps at a law that does not cover the band (a geometric band reaching 1, whose
high end has no "not yet") is not used, and the answer says so.

``objective = "min"``: the complement is maximised (the ``sensed-constrained`` route
builds the complement's automaton, whose ``accept`` marks the runs failing the task);
each candidate is judged in those terms (nature making the complement as unlikely, the
task as likely, as it can), the upper bounds are the complement's at each law, and the
bracket is read back, ``upper`` the returned controller's worst case (as
:mod:`mitld_lp.routes.sensed_band` reads a minimum).

False alarms at a band that may never happen (:mod:`mitld_lp.routes.sensed_never`,
"Under a band"): every candidate is built blind, its reports dropped
(:meth:`SensedConstrainedRoute.build`), so the answer above is the blind controller's,
whose task and constraint values over the band are those it has in the posed problem
(the reports move neither world, task nor nature's choices); it is bracketed against
this route's answer with the more informative sensor without false alarms, whose
``upper`` bounds every posed controller meeting the constraints under every law (each
of its bounds is a constrained optimum at a law of the band, or the unconstrained
band's).  With ``then`` the steps are the blind controller's worst case, as above.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

import numpy as np

from mitld_lp.automata.dta import SAFE
from mitld_lp.checks import Check
from mitld_lp.logic.syntax import atoms
from mitld_lp.problem import Posed
from mitld_lp.result import Result
from mitld_lp.routes.constrained import ConstraintValue
from mitld_lp.routes.robust_constrained import alone_bounds
from mitld_lp.routes.route import Route
from mitld_lp.routes.sensed_constrained import SensedConstrainedPart, SensedConstrainedRoute
from mitld_lp.sensing.sensors import partial
from mitld_lp.solvers.result import Status
from mitld_lp.solvers.rounding import float_up, one_minus

__all__ = ["SensedBandConstrainedRoute", "SensedBandConstrainedPart", "Judged", "judge",
           "ROUNDS", "covers"]

log = logging.getLogger(__name__)

ROUNDS = 6
"""How many times a law's LP is solved again with the bounds the band breaks tightened."""

HALVINGS = 4
"""How many times a tightened LP found infeasible is solved again, its margins halved."""


@dataclass(frozen=True, slots=True, eq=False)
class SensedBandConstrainedPart(SensedConstrainedPart):
    """The ``sensed-constrained`` part of an answer with a band: the chosen law's, and
    the band's bounds (``worst``: the chosen controller's :class:`Judged`)."""

    worst: Any = None
    chosen_at: str = "middle law"
    point_uppers: Mapping[str, float] = field(default_factory=dict)
    band_worst = True


@dataclass(frozen=True, slots=True)
class Judged:
    """A candidate's worst case over the band on its interval chain: the task's
    ``lower`` (and ``truncated_won``, its runs past a truncation point counted won),
    each constraint's value with the bounds nature drives it to, whether all hold,
    the expected steps nature maximises and, with ``then = "min-cost"``, the expected
    cost (``(value, upper)``; NaN where not asked), the chain's states."""

    lower: float
    truncated_won: float
    values: tuple[ConstraintValue, ...]
    steps: tuple[float, float]
    cost: tuple[float, float]
    n_states: int

    @property
    def holds(self) -> bool:
        return all(v.holds for v in self.values)


def judge(result: Result, constraints: tuple[Any, ...],
          max_states: int | None = None) -> Judged:
    """The worst case over the band of ``result``'s controller (module docs), against
    the problem's ``constraints`` (``result``'s may be tightened ones, in their order)."""
    from mitld_lp.running.sensed_band_chain import nature_max, reach_min, sensed_band_unfolding_of

    chain, rewards = sensed_band_unfolding_of(result, max_states=max_states)
    reward = dict(rewards)
    labels = chain.labels

    def marked(name: str) -> np.ndarray:
        return np.array([name in x for x in labels], dtype=bool)

    accept, truncated = marked("accept"), marked("truncated")
    values = []
    for i, c in enumerate(constraints, start=1):
        if c.kind == "prob" and c.sense == ">=":
            lo = reach_min(chain, marked(f"c{i}"))
            values.append(ConstraintValue(c, lo, lo >= c.bound, bounds=(lo, 1.0)))
            continue
        nm = (nature_max(chain, target=marked(f"c{i}")) if c.kind == "prob" else
              nature_max(chain, reward=reward[c.kind]))
        values.append(ConstraintValue(c, nm.value, nm.proven and nm.upper <= c.bound,
                                      bounds=(nm.value, nm.upper)))
    nan = (float("nan"), float("nan"))
    then = result.part.then
    cost = nan
    nm = nature_max(chain, reward=reward["steps"])  # the answer's E(steps): the worst law's
    steps = (nm.value, nm.upper)
    if then == "min-cost":
        nm = nature_max(chain, reward=reward["cost"])
        cost = (nm.value, nm.upper)
    return Judged(reach_min(chain, accept), reach_min(chain, accept | truncated),
                  tuple(values), steps, cost, chain.n_states)


class SensedBandConstrainedRoute(Route):
    """Constraints or ``then`` with a sensor that misses its event and a band (module
    docs): the ``sensed-constrained`` route's controllers judged over the band.
    ``every``: it claims such problems without constraints too (the trade-off curve's
    end points, which the sensed constrained route would answer at the middle law)."""

    name = "sensed-constrained"
    takes_constraints = True
    observation_based = True

    def __init__(self, *, every: bool = False) -> None:
        self.every = every

    def claims(self, posed: Posed) -> bool:
        return bool(partial(posed.model.sensors)) and posed.robust \
            and (posed.problem.constrained or self.every)

    def refusal(self, posed: Posed) -> list[str]:
        from mitld_lp.problem import complement_class

        # the sensed-constrained route's own conditions at a point law for the task
        # maximised (its class, the sensors'); the band, and a minimum with it (the
        # complement maximised, module docs), are this route's
        asked = replace(posed, robust=False)
        if posed.minimise:
            asked = replace(asked, fragment=complement_class(posed.fragment),
                            problem=replace(posed.problem, objective="max"))
        refused = SensedConstrainedRoute(every=self.every).refusal(asked)
        return refused + [x for x in alarm_band_refusals(posed.model, worst=True)
                          if x not in refused]

    def build(self, posed: Posed, progress: bool | None = None) -> Any:
        """The joint automaton and its information-state product at the band's middle
        law (:meth:`SensedConstrainedRoute.build`)."""
        return SensedConstrainedRoute().build(posed, progress=progress)

    def solve(self, posed: Posed, built: Any, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.routes.sensed_never import never_alarms, solve_never_band

        result = _solve(posed, built, costs=costs, seed=seed)
        if not never_alarms(posed.model):
            return result
        # false alarms at a band that may never happen: every candidate was built blind,
        # its reports dropped (SensedConstrainedRoute.build), so ``result`` is the blind
        # end's; the informed end on this route, its sensor kept sensed where it reports
        # surely and at once (sensed_never.KeptSensor: the robust constrained route does
        # not truncate such a band)
        return solve_never_band(posed, result, (SensedBandConstrainedRoute(every=True),),
                                costs=costs)


def alarm_band_refusals(model: Any, *, worst: bool = False) -> list[str]:
    """Why a sensor with false alarms is not solved under a band (empty: it is, or none
    has them; :func:`mitld_lp.routes.sensed.false_alarm_refusal`).  ``worst``: the
    caller solves the band's worst case (this route: its candidates are the sensed
    constrained route's solves with false alarms at the band's laws, each judged on its
    interval chain, which draws every step's report; at a band that may never happen
    built blind and bracketed: module docs), so none is refused; else every false alarm
    is, the message naming the routes that solve it (the band's best law is the sensed
    optimistic constrained route's, a band that may never happen bracketed there too:
    :mod:`mitld_lp.routes.sensed_optimistic_constrained`).  The sensed
    constrained route builds false alarms at a point law only, so the band routes that
    call its refusal at one add this."""
    from mitld_lp.routes.sensed import false_alarm_refusal

    return [x for a, s in sorted(partial(model.sensors).items()) if s.false_alarm
            for x in false_alarm_refusal(a, s.false_alarm, model.distributions.get(a),
                                         never=worst, robust=True, worst=worst)]


def covers(result: Result) -> bool:
    """Whether the law ``result``'s information states were built at gives every outcome
    of a step that some law of its band gives (module docs): at each clock of each band
    event, its hazard positive where the band's greatest is, below 1 where the band's
    least is.  A band that no truncation serves
    (:class:`~mitld_lp.distributions.band.TailBand`, :func:`mitld_lp.sensing.belief.
    sensed_sta`) may still bring its event past the law's cut, which the information
    states do not hold: a stay's verdicts stand then only where that event changes none
    (a co-safe task's, accepted or not already; a constraint's formula that does not
    name it, the world ignoring it), so a task with a safety part, or a constraint
    naming the event, is not covered."""
    from mitld_lp.distributions.band import TailBand

    for c in result.sta.clocks.values():
        if not c.distribution.is_ambiguous:
            continue
        if isinstance(c.distribution, TailBand) and c.distribution.hi > 0.0:
            dta = result.joint.dta if result.joint is not None else result.dta
            if SAFE in dta.kinds or any(
                    c.event in atoms(v.constraint.formula) for v in result.constraints
                    if getattr(v.constraint, "formula", None) is not None):
                return False
        for t in range(c.cap + 1):
            h, (lo, hi) = c.hazard(t), c.band(t)
            if (hi > 0.0 and h <= 0.0) or (lo < 1.0 and h >= 1.0):
                return False
    return True


def _stays(result: Result) -> bool:
    """Whether ``result``'s policy stays (or keeps) anywhere with positive probability."""
    part = result.part
    prob, merged = getattr(part, "prob", None), getattr(part, "merged", None)
    return prob is not None and merged is not None and bool(np.any(prob[merged.keep] > 0))


def _terms(r: Result) -> tuple[float, float]:
    """``r``'s bracket in the solved automaton's terms: a minimum's complement's."""
    if r.complemented:
        return r.complement if r.complement is not None else (1.0 - r.upper, 1.0 - r.lower)
    return r.lower, r.upper


def _at(posed: Posed, laws: Mapping[str, Any] | None, cons: tuple[Any, ...] | None) -> Posed:
    """``posed`` with the band's point law ``laws`` (None: as posed) and the constraints
    ``cons`` (None: as posed)."""
    problem = posed.problem
    if laws is not None:
        model = dataclasses.replace(posed.model, distributions=MappingProxyType(dict(laws)))
        problem = replace(problem, model=model)
    if cons is not None:
        problem = replace(problem, constraints=cons)
    return replace(posed, problem=problem)


def _tightened(cons: tuple[Any, ...], margins: list[float]) -> tuple[Any, ...]:
    """The constraints with each bound moved in by its margin (a probability's kept in
    [0, 1], an expected total's at least 0)."""
    out = []
    for c, step in zip(cons, margins, strict=True):
        bound = c.bound - step if c.sense == "<=" else c.bound + step
        out.append(replace(c, bound=min(max(bound, 0.0), 1.0) if c.kind == "prob"
                           else max(bound, 0.0)))
    return tuple(out)


def _tighten(inner: SensedConstrainedRoute, here: Posed, b: Any, j: Judged, label: str,
             costs: Mapping[str, float] | None, seed: int | None
             ) -> list[tuple[str, Result, Judged]]:
    """``here``'s LP (a law of the band, built ``b``, judged ``j``) solved again with each
    bound the band breaks moved in by what the band added and a little more, a bound
    missed again by at least twice its last step; an LP infeasible so tightened is
    solved again with the margins halved back towards the last feasible ones
    (:data:`HALVINGS` times), as the fully observed band constrained route tightens
    (:func:`mitld_lp.routes.robust_constrained.tighten_margins`); at most :data:`ROUNDS`
    rounds, until a candidate meets every bound under every law.  The candidates
    judged, in order."""
    from mitld_lp.routes.robust_constrained import tighten_margins

    cons = here.problem.constraints
    margins, steps = [0.0] * len(cons), [0.0] * len(cons)
    out: list[tuple[str, Result, Judged]] = []
    for attempt in range(1, ROUNDS + 1):
        good = list(margins)  # the last margins whose LP was feasible
        margins = tighten_margins(j.values, margins, steps)
        for halved in range(HALVINGS + 1):
            r = inner.solve(_at(here, None, _tightened(cons, margins)), b, costs=costs,
                            seed=seed)
            if r.controller is not None or halved == HALVINGS:
                break
            margins = [0.5 * (x + y) for x, y in zip(good, margins, strict=True)]
        if r.controller is None or (_stays(r) and not covers(r)):
            break
        steps[:] = [x - y for x, y in zip(margins, good, strict=True)]  # the step taken
        j = judge(r, cons, here.settings.max_states)
        out.append((f"{label}, tightened {attempt}", r, j))
        if j.holds:
            break
    return out


def _solve(posed: Posed, built: Any, *, costs: Mapping[str, float] | None,
           seed: int | None) -> Result:
    from mitld_lp.routes.sensed_band import blind_at, end_laws

    t0 = time.perf_counter()
    inner = SensedConstrainedRoute()
    s = posed.settings
    cons = posed.problem.constraints
    uppers: dict[str, float] = {}
    tried: list[tuple[str, Result, Judged]] = []
    first: Result | None = None
    laws_to_try: list[tuple[str, Mapping[str, Any] | None]] = [
        ("middle law", None), *end_laws(posed.model.distributions)]
    at: dict[str, tuple[Posed, Any]] = {}
    skipped: list[str] = []
    for label, laws in laws_to_try:  # each law's own LP, judged
        here = _at(posed, laws, None)
        b = built if laws is None else inner.build(here, progress=s.progress)
        r = inner.solve(here, b, costs=costs, seed=seed)
        first = first or r
        if r.status is Status.INFEASIBLE:  # infeasible at a law of the band
            return replace(r, model=posed.model, bands=_bands(r), part=replace(
                r.part, message=f"infeasible at the band's {label}, so under the band: "
                f"{r.part.message}"))
        if r.controller is None:
            continue
        if r.status is Status.OPTIMAL and not (laws is not None and blind_at(posed, laws)):
            uppers[label] = _terms(r)[1]  # not a blind build's (sensed_band.blind_at)
        if _stays(r) and not covers(r):
            log.info("the candidate at the band's %s stays where its law does not cover "
                     "the band: not used (module docs)", label)
            skipped.append(label)
            continue
        tried.append((label, r, judge(r, cons, s.max_states)))
        at[label] = (here, b)
    if tried and not any(j.holds for _, _, j in tried):
        # none holds under every law: the best one's law again, the bounds the band
        # breaks tightened by what it added
        label, _, j = max(tried, key=lambda t: t[2].lower)
        here, b = at[label]
        tried += _tighten(inner, here, b, j, label, costs, seed)
    assert first is not None
    good = [t for t in tried if t[2].holds]
    uppers["without constraints"] = _unconstrained_upper(posed)
    upper = min(u for u in (*uppers.values(), 1.0) if u == u)  # NaN: not given
    if not good:
        said = "; ".join(f"{name}: " + ", ".join(
            f"{v.constraint.text} worst case {v.certified:.6g}" for v in j.values
            if not v.holds) for name, _, j in tried) or "no controller at any law"
        if skipped:
            said += ("; not used, staying where the law does not give every outcome the "
                     "band gives: the candidate at the " + ", ".join(skipped))
        # each probability constraint alone, seeing every event: a bound no
        # observation-based controller betters (robust_constrained.alone_bounds)
        none, alone = alone_bounds(posed)
        values = tuple(replace(v, holds=False) for v in first.constraints)
        if none is not None:
            message = f"infeasible under the band: {none}"
            check = Check("constraints under every law of the band", False, message)
            return replace(first, model=posed.model, lower=float("nan"),
                           upper=float("nan"), value=float("nan"),
                           status=Status.INFEASIBLE, controller=None, certified=False,
                           checks=(*first.checks, check), bands=_bands(first),
                           part=replace(first.part, constraints=values, message=message),
                           timings={**first.timings, "band": time.perf_counter() - t0})
        message = ("failed: no candidate controller meets every constraint under every law "
                   f"of the band ({said}); whether one exists is not known" + (
                       f" (each bound is within what a controller seeing every event "
                       f"reaches: {alone})" if alone else ""))
        check = Check("constraints under every law of the band", False, message)
        return replace(first, model=posed.model, lower=float("nan"), upper=upper,
                       value=float("nan"), status=Status.FAILED, controller=None,
                       certified=False, checks=(*first.checks, check), bands=_bands(first),
                       part=replace(first.part, constraints=values, message=message),
                       timings={**first.timings, "band": time.perf_counter() - t0})
    name, r, j = max(good, key=lambda t: t[2].lower)
    lower = float(min(j.lower, upper))  # the complement's, for a minimum
    width = upper - lower
    cut = float(min(max(j.truncated_won - lower, 0.0), width))
    closed = width - cut <= s.precision * max(lower, 0.0)
    said = ", ".join(f"{k} {v!r}" for k, v in uppers.items())
    terms = "the complement's " if r.complemented else ""
    detail = (f"{terms}lower {lower!r}: the worst case over the band of the "
              f"sensed-constrained controller at the {name} on its chain ({j.n_states} "
              f"states); {terms}upper {upper!r}: the least of the constrained optima's upper "
              f"bounds at the band's laws ({said}); gap {width:.3g}, of which {cut:.3g} the "
              f"truncation's; the rest " + ("within" if closed else "beyond") +
              f" the precision {s.precision:g}" + (
                  f"; not used (staying where the law does not give every outcome the band "
                  f"gives): the candidate at the {', '.join(skipped)}" if skipped else ""))
    held = "; ".join(f"{v.constraint.text}: worst case {v.certified!r}" for v in j.values)
    checks = (*r.checks, Check("worst case over the band", closed, detail),
              Check("constraints under every law of the band", True, held or "none"))
    extra: dict[str, Any] = {}
    if not np.isnan(j.steps[1]):
        extra["steps"] = j.steps[1]
        if r.part.then is not None:
            ok = bool(np.isfinite(j.steps[1]))
            checks += (Check("worst expected steps over the band", ok,
                             f"E(steps) in [{j.steps[0]!r}, {j.steps[1]!r}] at the worst "
                             "law (nature maximising, proven from above)"),)
    if r.part.then == "min-steps":
        extra["secondary"] = j.steps[1]
    elif r.part.then == "min-cost":
        extra["secondary"] = j.cost[1]
        checks += (Check("worst expected cost over the band", bool(np.isfinite(j.cost[1])),
                         f"E(cost) in [{j.cost[0]!r}, {j.cost[1]!r}] at the worst law"),)
    bracket: tuple[float, float] = (lower, upper)
    complement = None
    if r.complemented:  # read back: Pmin(task) = 1 - Pmax(not task)
        complement, bracket = bracket, one_minus(lower, upper)
    message = ("" if closed else
               f"not certified: the worst case over the band of an observation-based "
               f"controller meeting the constraints under every law is in "
               f"[{bracket[0]!r}, {bracket[1]!r}] (gap {width:.3g}); both ends sound")
    part = SensedBandConstrainedPart(
        **{f.name: getattr(r.part, f.name) for f in dataclasses.fields(r.part)},
        worst=j, chosen_at=name, point_uppers=uppers)
    part = replace(part, constraints=j.values, message=message or r.part.message, **extra)
    result = replace(r, model=posed.model, lower=bracket[0], upper=bracket[1],
                     value=bracket[1] if r.complemented else bracket[0],
                     complement=complement, certified=all(c.passed for c in checks),
                     checks=checks, part=part,
                     bands=_bands(r), width={"total": width, "truncation": cut,
                                             "band": max(width - cut, 0.0)},
                     timings={**r.timings, "band": time.perf_counter() - t0})
    log.info("sensed constrained synthesis over the band: [%r, %r], certified=%s",
             result.lower, result.upper, result.certified)
    return result


def _unconstrained_upper(posed: Posed) -> float:
    """The sensed optimum's upper bound over the band without the constraints and
    ``then`` (:mod:`mitld_lp.routes.sensed_band`): no controller meeting them does
    better; NaN, said in the log, where that route does not give it (a budget, a
    refusal, a time limit)."""
    from mitld_lp.problem import ProblemError, pose_on
    from mitld_lp.routes.sensed import SensedRoute
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.util.memory import ProductTooLarge

    settings = replace(posed.settings, progress=False)
    try:
        model = dataclasses.replace(posed.model, constraints=())
        alone = pose_on([SensedRoute()], model, settings=settings,
                        objective=posed.problem.objective)
        r = alone.route.solve(alone, build_posed(alone, progress=False))
    except (ProblemError, ProductTooLarge) as exc:
        log.info("the sensed optimum over the band without constraints not used: %s", exc)
        return float("nan")
    if r.controller is None:
        return float("nan")
    if posed.minimise and not r.complemented:  # the complement's upper, read back
        return r.complement[1] if r.complement is not None else float_up(1.0 - r.lower)
    return _terms(r)[1]


def _bands(r: Result) -> dict[str, str]:
    return {e: str(c.distribution) for e, c in sorted(r.sta.clocks.items())
            if c.distribution.is_ambiguous}
