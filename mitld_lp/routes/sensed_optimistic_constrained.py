"""Constraints (and ``then``) with a sensor that misses its event and a band read for its
best law (``bands = "best"``): the best task probability over the pairs (an
observation-based controller, a law of the band) under which every constraint holds,
bracketed soundly.

Read optimistically, nature helps with everything, as on the fully observed route
(:mod:`mitld_lp.routes.optimistic_constrained`): the constraints are met *under the law
the pair names*, not under every law.  The candidates here are the sensed constrained
optimum (:mod:`mitld_lp.routes.sensed_constrained`, a randomised controller over the
information states) with the band at a constant law of its own: its middle law, every
band at its low end, every band at its high end
(:func:`mitld_lp.routes.sensed_band.end_laws`).  Each is certified at that law by its
route: its task value from below, each constraint on the side that matters (a sensor
with false alarms too, at a band whose laws surely happen: the sensed constrained route
builds them at a point law).  That law
is one nature may play (a hazard inside the band at every step), so a candidate whose
every constraint holds is a pair of the kind posed, and ``lower`` is the best such
candidate's task value (for ``objective = "min"`` ``upper`` is its task value, the
least).  The answer's model is the candidate's, at that law: its controller, its chain
(``export --chain``: Storm's ``P=? [F "accept"]`` at least ``lower``, each ``c<i>``
within its bound) and its runs (``simulate``) are at the law nature chose.

The other end is the fully observed optimistic constrained optimum (the robust
constrained route with ``bands = "best"``, the sensors read as perfect): an (action,
corner) occupancy LP over every pair of a full-information policy and a law of the band
meeting the constraints, which contains every observation-based pair; its ``upper``
(for a minimum its ``lower``) bounds the optimum posed.  Nature restricted to constant
laws and the robot to what it observes make the bracket open in general; the check
``best case over the band`` says the gap, certified where it closes within the
precision, the whole gap counted (the candidate's own truncation width at its law is
reported in ``width``, but how much of the gap to the other end is the truncation's is
not known for a pair, so none of it is taken off).  With ``then`` the second
objective is the candidate's at its law (its expected steps or cost, as its route
computes them).  If no candidate meets its constraints, the middle law's answer is
returned with its status (no constraint said to hold) and not certified; ``infeasible``
there stays so only where the fully observed problem is infeasible too (it holds every
pair), else the status is ``failed`` (another law of the band may admit a pair).

False alarms at a band that may never happen (:mod:`mitld_lp.routes.sensed_never`,
"Under a band"): every candidate is built blind, its reports dropped
(:meth:`SensedConstrainedRoute.build`; :class:`PointLawRoute` solves it at its law
without bracketing it there), so the answer above is the blind controller's at nature's
chosen law, whose task and constraint values there are those it has in the posed
problem; it is bracketed against this route's answer with the more informative sensor
without false alarms, whose ``upper`` bounds every posed pair.  The fully observed
bound is not given for such a band (the robust constrained route cannot truncate it:
NaN, said in the log): the informed end's ``upper`` is then 1 (for a minimum its
``lower`` 0), the bracket sound but only the blind controller's end informative.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.problem import Posed
from mitld_lp.result import Result
from mitld_lp.routes.sensed_constrained import SensedConstrainedPart, SensedConstrainedRoute
from mitld_lp.routes.stages import Built
from mitld_lp.sensing.sensors import partial
from mitld_lp.solvers.result import Status
from mitld_lp.solvers.rounding import one_minus

__all__ = ["SensedOptimisticConstrainedRoute", "SensedOptimisticConstrainedPart",
           "PointLawRoute", "point_laws", "solve_sensed_optimistic_constrained"]

log = logging.getLogger(__name__)

#: What such an answer says of its controller.
SENSED_OPTIMISTIC_CONSTRAINED = (
    "the bands read for the robot's best law (Pmaxmax) with sensors that miss events and "
    "constraints: the controller acts on observations and meets the constraints at the "
    "law of the bands it is played with (the answer's model), not under every law "
    "(bands 'worst' gives the guarantee)")


@dataclass(frozen=True, slots=True, eq=False)
class SensedOptimisticConstrainedPart(SensedConstrainedPart):
    """The chosen candidate's ``sensed-constrained`` part, with the law it was solved at
    (``chosen_at``), each candidate's task value (``tried``) and the fully observed
    optimistic constrained optimum's bound (``full_bound``)."""

    chosen_at: str = "middle law"
    tried: Mapping[str, float] | None = None
    full_bound: float = float("nan")
    reading: str = "best"


def point_laws(distributions: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The constant laws of the band tried: every band at its middle law, at its low
    ends and at its high ends (:func:`mitld_lp.routes.sensed_band.end_laws`), each as
    point laws (the other laws unchanged)."""
    from mitld_lp.routes.sensed_band import end_laws

    def points(laws: Mapping[str, Any]) -> dict[str, Any]:
        return {e: d.nominal if d.is_ambiguous else d for e, d in laws.items()}

    return [("middle law", points(distributions)),
            *((name, points(laws)) for name, laws in end_laws(distributions))]


class SensedOptimisticConstrainedRoute(SensedConstrainedRoute):
    """Constraints or ``then``, a sensor that misses its event and a band read for its
    best law (module docs): the sensed constrained route's answer at the band's
    constant laws, the fully observed optimistic constrained optimum as the other end.
    ``every``: it claims such problems without constraints too (the trade-off curve's
    end points, :mod:`mitld_lp.tradeoff`)."""

    optimistic = True

    def claims(self, posed: Posed) -> bool:  # every: without constraints too (pareto)
        return (bool(partial(posed.model.sensors)) and posed.robust
                and posed.settings.bands == "best"
                and (posed.problem.constrained or self.every))

    def refusal(self, posed: Posed) -> list[str]:
        """The sensed constrained route's refusals at the band's middle law (the band
        itself is taken here; false alarms with it too, each candidate a point law's
        solve with them, except where a law may never happen)."""
        from mitld_lp.routes.sensed import false_alarm_refusal

        at = _at_law(posed, point_laws(posed.model.distributions)[0][1])
        refused = SensedConstrainedRoute.refusal(self, at)
        alarms = [x for a, s in sorted(partial(posed.model.sensors).items()) if s.false_alarm
                  for x in false_alarm_refusal(a, s.false_alarm,
                                               posed.model.distributions.get(a),
                                               never=True, robust=True, best=True)]
        return refused + [x for x in alarms if x not in refused]

    def build(self, posed: Posed, progress: bool | None = None) -> Built | None:
        return None  # each candidate builds its own product, at its own law

    def solve(self, posed: Posed, built: Built | None, *,
              costs: Mapping[str, float] | None = None, seed: int | None = 0) -> Result:
        from mitld_lp.routes.sensed_never import never_alarms, solve_never_band

        result = solve_sensed_optimistic_constrained(posed, costs=costs, seed=seed)
        if not never_alarms(posed.model):
            return result
        # false alarms at a band that may never happen: every candidate was built blind,
        # its reports dropped, so ``result`` is the blind end's; the informed end on this
        # route (module docs)
        return solve_never_band(posed, result,
                                (SensedOptimisticConstrainedRoute(every=True),), costs=costs)


class PointLawRoute(SensedConstrainedRoute):
    """The sensed constrained route at one of the band's constant laws, as a candidate:
    its answer at that law, not bracketed where a sensor with false alarms has a law
    that may never happen (built blind, its reports dropped:
    :meth:`SensedConstrainedRoute.build`); the band's answer is bracketed as a whole
    (:meth:`SensedOptimisticConstrainedRoute.solve`)."""

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        return self._solve(posed, built, costs=costs, seed=seed)


def _at_law(posed: Posed, laws: Mapping[str, Any]) -> Posed:
    """``posed`` with the model's laws ``laws`` (point laws: not robust)."""
    model = dataclasses.replace(posed.model, distributions=MappingProxyType(dict(laws)))
    return replace(posed, problem=replace(posed.problem, model=model), robust=False,
                   route=PointLawRoute())


def _full_bound(posed: Posed) -> tuple[float, bool]:
    """The fully observed optimistic constrained optimum's sound end for the same
    problem (its sensors read as perfect): its ``upper`` for a maximum, its ``lower``
    for a minimum; NaN, said in the log, where that route does not give it (a budget, a
    refusal, a band it cannot truncate: one whose laws may never happen, its upper
    survival above every share).  And whether that problem is infeasible (no pair of a
    full-information policy and a law of the band meets the constraints, so no
    observation-based one does)."""
    from mitld_lp.distributions import DistributionError
    from mitld_lp.problem import ProblemError, pose_on
    from mitld_lp.routes.robust_constrained import RobustConstrainedRoute
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.util.memory import ProductTooLarge

    p = posed.problem
    model = dataclasses.replace(p.model, sensors=MappingProxyType({}), constraints=())
    try:
        seen = pose_on([RobustConstrainedRoute(every=True)], model, p.constraints,
                       then=p.then,
                       settings=replace(posed.settings, progress=False),
                       objective=p.objective)
        full = seen.route.solve(seen, build_posed(seen, progress=False))
    except (ProblemError, ProductTooLarge, DistributionError) as exc:
        log.info("fully observed optimistic constrained bound not used: %s", exc)
        return float("nan"), False
    return float(full.lower if posed.minimise else full.upper), full.status == Status.INFEASIBLE


def _holds(r: Result) -> bool:
    return (r.status == Status.OPTIMAL and r.controller is not None
            and all(v.holds for v in r.constraints))


def solve_sensed_optimistic_constrained(posed: Posed, *,
                                        costs: Mapping[str, float] | None = None,
                                        seed: int | None = 0) -> Result:
    """Solve the problem of the module docs: the candidates at the band's constant laws,
    the fully observed optimistic constrained bound."""
    from mitld_lp.routes.sensed_band import within_time

    t0 = time.perf_counter()
    s, limit, minimise = posed.settings, posed.settings.time_limit, posed.minimise
    bands = {e: str(d) for e, d in sorted(posed.model.distributions.items())
             if d.is_ambiguous}
    own = (lambda r: r.upper) if minimise else (lambda r: r.lower)  # the controller's end
    tried: dict[str, float] = {}
    chosen: tuple[Result, str] | None = None
    first: Result | None = None
    for label, laws in point_laws(posed.model.distributions):
        timed = within_time(posed, t0, limit, label)
        if timed is None:
            continue
        at = _at_law(timed, laws)
        r = at.route.solve(at, at.route.build(at, progress=s.progress), costs=costs,
                           seed=seed)
        first = first or r
        if not _holds(r):
            continue
        tried[label] = float(own(r))
        if chosen is None or (own(r) < own(chosen[0]) if minimise else
                              own(r) > own(chosen[0])):
            chosen = (r, label)
    timed = within_time(posed, t0, limit, "the fully observed optimistic constrained optimum")
    full, full_infeasible = (float("nan"), False) if timed is None else _full_bound(timed)
    if chosen is None:  # no candidate meets its constraints: the middle law's status
        assert first is not None
        # infeasible at the middle law is infeasible under the band only where the fully
        # observed problem, which holds every pair, is infeasible too
        unproved = first.status == Status.INFEASIBLE and not full_infeasible
        said = ("; infeasible at the band's middle law, not proved for the band (the fully "
                "observed optimistic constrained problem, which holds every pair, is not "
                "infeasible or not solved): another law may admit a pair" if unproved else "")
        return replace(first, bands=bands, certified=False,
                       status=Status.FAILED if unproved else first.status, part=_part(
                           first, "middle law", tried, full,
                           f"{first.part.message}; no candidate (the band's middle law and "
                           "ends) meets the constraints: no pair of an observation-based "
                           "controller and a law of the band found" + said + "; "
                           + SENSED_OPTIMISTIC_CONSTRAINED))
    r, name = chosen
    # in the maximised automaton's terms (a minimum: the complement's), then read back
    low = 1.0 - float(r.upper) if minimise else float(r.lower)
    high = min(x for x in ((1.0 - full) if minimise else full, 1.0) if x == x)
    agree = low <= high + s.precision * max(high, 0.0)
    high = max(high, low)
    width = high - low
    cut = min(float(r.width.get("truncation", 0.0)), width)  # the candidate's own, at its law
    closed = agree and width <= s.precision * max(low, 0.0)  # the pair's share not apart
    terms = "the complement's " if minimise else ""
    said = ", ".join(f"{k} {v!r}" for k, v in tried.items())
    detail = (f"{terms}lower {low!r}: the sensed constrained optimum at the {name}, its "
              f"constraints met at that law (candidates meeting theirs: {said}); {terms}"
              f"upper {high!r}: the fully observed optimistic constrained optimum's "
              f"({full!r}); gap {width:.3g} (the candidate's own truncation at its law "
              f"{cut:.3g}, not taken off: how much of the gap is the truncation's is not "
              "known for a pair), " + ("within" if closed else "beyond")
              + f" the precision {s.precision:g}"
              + ("" if agree else "; the candidate is above the bound"))
    checks = (*r.checks, Check("best case over the band", closed, detail))
    bracket = one_minus(low, high) if minimise else (low, high)
    gap = "" if closed else (f"; not certified: the optimum is in [{bracket[0]!r}, "
                             f"{bracket[1]!r}] (gap {width:.3g}), both ends sound")
    widths = {**r.width, "total": width, "truncation": cut,
              "band": max(width - cut - float(r.width.get("solver", 0.0)), 0.0)}
    # (the candidate's truncation and solver parts, the rest the band's and the sensor's)
    result = replace(r, lower=bracket[0], upper=bracket[1],
                     value=bracket[1] if minimise else bracket[0],
                     complement=(low, high) if r.complement is not None else None,
                     certified=all(c.passed for c in checks), checks=checks, bands=bands,
                     width=widths, part=_part(r, name, tried, full, (
                         f"{r.part.message}; {SENSED_OPTIMISTIC_CONSTRAINED}{gap}")),
                     timings={**r.timings, "band": time.perf_counter() - t0})
    log.info("sensed constrained synthesis, the band's best law: [%r, %r], certified=%s",
             result.lower, result.upper, result.certified)
    return result


def _part(r: Result, name: str, tried: Mapping[str, float], full: float, message: str
          ) -> SensedOptimisticConstrainedPart:
    """``r``'s part as this route's, with its law, candidates, bound and message."""
    fields = {f.name: getattr(r.part, f.name) for f in dataclasses.fields(r.part)}
    fields.update(chosen_at=name, tried=dict(tried), full_bound=full, message=message)
    return SensedOptimisticConstrainedPart(**fields)
