"""False alarms with an event law that may never happen (``never > 0``), bracketed on
the ``sensed`` route, and with constraints, ``then`` or the trade-off curve on the
``sensed-constrained`` route, instead of refused.  On a world whose moves react to the
event the same bracket is built on the ``sensed-reacting`` route (and
``sensed-constrained`` on its product), each end a reacting product's solve
(:mod:`mitld_lp.routes.sensed_reacting`): the blind end still reads the world's moves,
and the garbling below leaves them alone, so both arguments hold as they are.

Such a sensor reports or not at every step, and the belief that its event never happens
moves with every report for ever: the information state is not finite
(:func:`mitld_lp.routes.sensed.false_alarm_refusal`).  The posed optimum (over every
controller that reads the world and every step's reports) is bracketed by two problems
the ``sensed`` route solves exactly as posed:

* **a controller that ignores the reports** (information horizon 0): the product built
  with each such sensor *blind* (``detect = 0``, no false alarms: it never reports), the
  sensor's reports then dropped by the controller (``Belief.ignored``, as for reports
  that come too late: :mod:`mitld_lp.sensing.horizon`).  Reports do not move the world
  or the task, so such a controller has in the posed problem the value it has there:
  its certified ``lower`` (for a maximum; its ``upper`` for a minimum) bounds the posed
  optimum, and it is the controller returned (its chain, tree and rollouts the posed
  model's, each report drawn and dropped).
* **a sensor at least as informative** (Blackwell): a sensor without false alarms
  reporting from ``K + delay`` on with ``d' = (d - f) / (1 - f)`` when ``d >= f`` (with
  ``d' = (f - d) / f`` when ``d < f``).  Its every-step reports ``r'`` give the posed
  sensor's by a garbling fixed in advance: report whenever ``r'`` does and otherwise with
  probability ``f`` (for ``d < f``: never when ``r'`` does, otherwise with probability
  ``f``), which reports with probability ``f`` before ``K + delay`` and ``d`` from it on,
  step by step independently.  So every controller of the posed problem is one of that
  sensor's (with a private coin, which no optimum needs), and that problem's certified
  ``upper`` (for a minimum its ``lower``) bounds the posed optimum.  Without false alarms
  the every-step reports after the first tell nothing (docs/semantics.md), so the route's
  first-report product solves it.

The bracket is certified (check ``false alarms, law that may never happen``) where the two
ends meet within the wider of the two solves' own brackets plus the precision: where the
reports cannot change the optimum.  Otherwise the check says the gap and its cause (the
reports' information, not read); ``Result.width["information"]`` is that gap.

**With constraints** (bounds on other formulas, on expected steps or cost; route
``sensed-constrained``) both ends are constrained optima, the same constraints posed.
The blind end's randomised controller ignores the reports, and the reports move neither
world nor task, so its task value *and each constraint's value* are those it has in the
posed problem: it meets the constraints exactly as certified, its value ``lower`` (for a
minimum ``upper``), and it is the controller returned (its chain draws and drops every
report).  Every posed controller is one of the informed sensor's with the same task and
constraint values (the garbling above), so the informed constrained optimum bounds the
posed one.  Where no blind controller meets the constraints: ``infeasible`` when the
informed problem is infeasible too (proved: it holds every posed controller), else
``failed`` with the informed end's bound and no controller (one reading the reports may
meet them).  **With** ``then`` the returned controller's expected steps (cost) are the
blind solve's, exact for it; where the first objective's ends meet, every posed
controller reaching the optimum is one of the informed problem's reaching it, with the
same steps, so the posed lexicographic optimum lies between the two ends' second
objectives: the check also asks those to meet.  The trade-off curve's points are each
this route's answer.

**Under a band** (a law known only within a band whose laws may never happen, its worst
law or ``bands = "best"`` its best, route ``sensed``: :func:`solve_never_band`; with
constraints or ``then`` its worst law on the sensed band constrained route,
:mod:`mitld_lp.routes.sensed_band_constrained`, its best law on the sensed optimistic
constrained route, :mod:`mitld_lp.routes.sensed_optimistic_constrained`) both ends are
the band's problems, posed with the same band.
The blind end is the band's solve on the product built blind, its controller dropping
the reports (:mod:`mitld_lp.routes.sensed_band`, :mod:`mitld_lp.routes.
sensed_optimistic`): its worst (best) case over the band is the one it has in the
posed problem, the reports moving neither world, task nor nature's choices, and its
interval chain draws and drops every step's report.  The informed end is the band's
problem with the more informative sensor, whose ``upper`` bounds every posed controller
under the band: each of the band route's upper bounds is the optimum at a law nature
may play at every step, or the fully observed one, and every posed controller is one
of the informed sensor's (the garbling above).  With constraints the same holds of
each constraint's value, as with a point law; with ``then`` each end's second objective
is its controller's worst case over the band, not an optimum, so only the returned
controller's is said.  With ``bands = "best"`` and constraints each end is the optimistic
constrained answer (a pair of a controller and a constant law of the band, the
constraints met at that law): the blind one's pair is one of the posed problem's (its
controller drops the reports, which move neither world, task nor the law), so its task
value at its law bounds the posed optimum (``lower``; an optimistic value, as every
``bands = "best"`` answer); every posed pair is one of the informed sensor's (the
garbling above, at the same law), so the informed end's ``upper`` bounds it.  The
informed end's sensor reports surely and at once where the posed one detects surely (or
never): it is kept on the sensed routes (:class:`KeptSensor`), whose information-state
product truncates such a band, which the fully observed robust routes cannot."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.problem import Posed, Route
from mitld_lp.result import Result
from mitld_lp.sensing.sensors import Sensor, partial
from mitld_lp.solvers.result import Status
from mitld_lp.solvers.rounding import one_minus

__all__ = ["KeptSensor", "never_alarms", "blind_model", "informed_model", "informed_detect",
           "solve_never", "solve_never_band", "dropping"]

log = logging.getLogger(__name__)


def never_alarms(model: Any) -> list[str]:
    """The events whose sensor gives false alarms and whose law may never happen."""
    return sorted(a for a, s in model.sensors.items()
                  if s.false_alarm > 0.0 and a in model.distributions
                  and float(model.distributions[a].never) > 0.0)


def informed_detect(detect: float, false_alarm: float) -> float:
    """``d'``: the detection of a sensor without false alarms whose reports, garbled,
    give those of a sensor with ``detect`` and ``false_alarm`` (module docs)."""
    if detect >= false_alarm:
        return (detect - false_alarm) / (1.0 - false_alarm)
    return (false_alarm - detect) / false_alarm


def _with(model: Any, events: list[str], make: Any) -> Any:
    sensors = dict(model.sensors)
    for a in events:
        sensors[a] = make(sensors[a])
    return dataclasses.replace(model, sensors=MappingProxyType(sensors))


def blind_model(model: Any) -> Any:
    """``model`` with each sensor of :func:`never_alarms` blind (it never reports)."""
    return _with(model, never_alarms(model), lambda s: Sensor(0.0, 0.0, s.delay))


@dataclass(frozen=True, slots=True)
class KeptSensor(Sensor):
    """A sensor that reports its event the step it happens, surely (``detect = 1``, no
    false alarm, no delay), kept on the sensed routes instead of read as the fully
    observed semantics (:attr:`Sensor.perfect` false): the information-state product
    keeps "never" as a hypothesis of its own and truncates a band that may never happen
    (:func:`mitld_lp.sensing.belief.sensed_sta`), which the fully observed robust routes
    do not (the band's upper survival stays above every share).  With ``detect = 1`` a
    miss rules out every hypothesis that the event has happened, so its information
    states are the fully observed ones."""

    @property
    def perfect(self) -> bool:
        return False


def informed_model(model: Any, *, keep: bool = False) -> Any:
    """``model`` with each sensor of :func:`never_alarms` replaced by the sensor without
    false alarms at least as informative (module docs).  ``keep``: one that reports
    surely and at once (``detect = 1``, no delay: the sensor with false alarms detects
    surely, or never) is a :class:`KeptSensor`, so that a band that may never happen
    stays on the sensed routes, which truncate it."""

    def informed(s: Sensor) -> Sensor:
        d = informed_detect(s.detect, s.false_alarm)
        return (KeptSensor if keep and d == 1.0 and s.delay == 0 else Sensor)(d, 0.0, s.delay)

    return _with(model, never_alarms(model), informed)


def dropping(belief: Any, model: Any) -> Any:
    """``belief``, built on :func:`blind_model` of ``model``, as the posed problem's: its
    sensors ``model``'s, the reports of :func:`never_alarms`' events dropped by the
    controller (``Belief.ignored``), so its chain, tree and rollouts draw each step's
    report from the posed sensor and drop it."""
    return dataclasses.replace(belief, sensors=partial(model.sensors),
                               ignored=belief.ignored | frozenset(never_alarms(model)))


def solve_never(posed: Posed, low: Result, routes: Sequence[Route], *,
                costs: Mapping[str, float] | None = None) -> Result:
    """The bracket of ``posed`` (module docs) from ``low``, the blind end solved (the
    route built its product with these sensors blind, their reports dropped by the
    controller: ``Belief.ignored``), and the informed problem solved here, with the
    same constraints, ``then``, objective and ``costs``, on the first of ``routes``
    that claims it (the caller's: the ``sensed`` route, or the plain one where every
    sensor left is perfect; with constraints or ``then`` the ``sensed-constrained``
    route, or the constrained one)."""
    from mitld_lp.problem import pose_on
    from mitld_lp.routes.stages import build_posed

    # the model's own constraints are among the posed problem's already
    # under a band the informed sensor stays sensed where it reports surely and at once
    # (KeptSensor): the fully observed robust routes do not truncate such a band
    informed = dataclasses.replace(informed_model(posed.model, keep=posed.robust),
                                   constraints=())
    settings = replace(posed.settings, progress=False)
    seen = pose_on(list(routes), informed, posed.problem.constraints,
                   then=posed.problem.then, settings=settings,
                   objective=posed.problem.objective)
    high = seen.route.solve(seen, build_posed(seen, progress=False), costs=costs)
    events = ", ".join(f"{a} (never {float(posed.model.distributions[a].never):.6g}, "
                       f"false_alarm {posed.model.sensors[a].false_alarm:g}, informed "
                       f"detect {informed_detect(posed.model.sensors[a].detect, posed.model.sensors[a].false_alarm):.6g})"  # noqa: E501
                       for a in never_alarms(posed.model))
    if not low.status.has_solution:
        return _unsolved(posed, low, high, events)
    minimum, ok, nan = posed.minimise, high.status.has_solution, float("nan")
    # max: the blind controller's lower, the informed optimum's upper; min: the informed
    # optimum's lower, the blind controller's upper
    lower = (high.lower if ok else nan) if minimum else low.lower
    upper = low.upper if minimum else (high.upper if ok else nan)
    if ok:
        lower = min(lower, upper)  # both bound the same optimum: only rounding can cross
    # each solve's own width (truncation, solver, ...), under a band less the band's part
    # (nature's choices): that gap is between the ends, not within one
    slack = max(_own(low), _own(high))
    # the width's parts: the wider solve's own, then the gap
    own = high.width if ok and _own(high) > _own(low) else low.width
    gap = max(upper - lower - slack, 0.0) if ok else nan
    # relative to ``lower``; under a band a minimum as its complement's maximum, as the
    # band's routes read it (relative to the complement's lower, ``1 - upper``)
    scale = 1.0 - upper if posed.robust and minimum else lower
    met = ok and gap <= (0.0 if posed.settings.precision != posed.settings.precision
                         else posed.settings.precision * max(scale, 0.0))
    steps, steps_met = _then(posed, low, high) if ok else ("", True)
    detail = (f"{events}: the controller ignores these reports (information horizon 0); "
              f"bracket [{lower:.7g}, {upper:.7g}] between it and a sensor without false "
              f"alarms at least as informative; " +
              (f"the informed problem is {high.status}, no bound from it" if not ok else
               "the ends meet: the reports cannot change the optimum" if met else
               f"gap {gap:.3g} beyond the solves' own widths: the reports' information, "
               "not read (a law that may never happen keeps the belief moving for ever)"
               + (", and nature's choices in the band" if posed.robust else ""))
              + steps)
    check = Check("false alarms, law that may never happen", bool(met and steps_met), detail)
    failed = tuple(Check(f"informed sensor: {c.name}", c.passed, c.detail)
                   for c in high.checks if not c.passed)
    checks = (*low.checks, *failed, check)
    log.info("false alarms with a law that may never happen: %s", detail)
    return replace(low, lower=lower, upper=upper, checks=checks,
                   certified=all(c.passed for c in checks),
                   status=low.status if not ok or low.status is high.status else
                   next(s for s in (low.status, high.status) if s.name != "OPTIMAL"),
                   complement=None if low.complement is None else one_minus(lower, upper),
                   width={**own, "total": upper - lower, "information": gap},
                   timings={**low.timings, "informed": high.seconds})


def solve_never_band(posed: Posed, low: Result, routes: Sequence[Route], *,
                     costs: Mapping[str, float] | None = None) -> Result:
    """The bracket of ``posed``, whose law that may never happen is known only within a
    band (module docs, "Under a band"), from ``low``, the band's problem solved on the
    product built with these sensors blind, their reports dropped; the informed end is
    the band's problem with the more informative sensor (a :class:`KeptSensor` where it
    reports surely and at once), read as ``posed`` reads the band (its worst or, ``bands
    = "best"``, its best law), with the same constraints, ``then`` and ``costs``, on the
    first of ``routes`` that claims it (the caller's: the band's sensed routes)."""
    return solve_never(posed, low, routes, costs=costs)


def _own(r: Result) -> float:
    """``r``'s bracket's width less its band's part (``width["band"]``: the gap between
    a controller's worst or best case and the band's bounds), NaN-free where it has no
    controller."""
    width = r.upper - r.lower - float(r.width.get("band", 0.0))
    return width if width == width else 0.0


def _then(posed: Posed, low: Result, high: Result) -> tuple[str, bool]:
    """With ``then``: the words on the second objective, and whether its ends meet.
    The returned controller's expected steps (cost) are the blind solve's, exact for it;
    where the first objective's ends meet, every posed controller reaching the optimum
    is one of the informed problem's reaching it, with the same steps and cost (the
    reports move neither world nor task), so the posed lexicographic optimum lies
    between the informed end's and the blind end's."""
    then = posed.problem.then
    if then is None or low.secondary is None or high.secondary is None:
        return "", True
    ours, least = float(low.secondary), float(high.secondary)
    what = "expected steps" if then == "min-steps" else "expected cost"
    if posed.robust:  # a band: each end's second objective is its controller's worst case
        # (read for the band's best law: its value at the law nature chose)
        at = ("at the band's law it is played with" if posed.settings.bands == "best"
              else "its worst case over the band")
        return (f"; then {then}: the controller's {what} {ours:.7g}, {at} (the blind "
                "solve's; the band's route proves no lexicographic optimum, so the ends' "
                "are not compared)"), True
    met = abs(ours - least) <= SECOND_TOL * max(1.0, abs(ours))
    return (f"; then {then}: the controller's {what} {ours:.7g} (the blind solve's), a "
            f"controller reading the reports at least {least:.7g}" +
            ("" if met else " (not met: reading the reports may be faster)")), met


#: The relative distance within which the two ends' second objectives (``then``) meet:
#: both are the lexicographic LPs' optima, each to the solver's tolerance.
SECOND_TOL = 1e-6


def _unsolved(posed: Posed, low: Result, high: Result, events: str) -> Result:
    """The answer where the blind end has no controller: infeasible where the informed
    problem is infeasible too (every posed controller is one of its, with the same
    constraint values: proved), else ``failed`` with the informed end's bound (a
    controller reading the reports may meet the constraints; none is claimed)."""
    if low.status != Status.INFEASIBLE:
        return low
    if high.status == Status.INFEASIBLE:
        said = (f"{events}: infeasible with the reports read too (a sensor without false "
                "alarms at least as informative: every controller of the posed problem is "
                "one of its, with the same constraint values)")
        return replace(low, checks=(*low.checks, Check(
            "false alarms, law that may never happen", True, said)))
    nan = float("nan")
    bound = (high.lower, nan) if posed.minimise else (nan, high.upper)
    said = (f"no controller ignoring the reports of {events} meets the constraints; "
            f"infeasibility is not proved (with a sensor without false alarms at least as "
            f"informative the problem is {high.status}, its optimum within "
            f"[{high.lower:.7g}, {high.upper:.7g}]): the reports' information, not read")
    log.info("false alarms with a law that may never happen: %s", said)
    return replace(low, status=Status.FAILED, lower=bound[0], upper=bound[1],
                   part=replace(low.part, message=said),
                   checks=(*low.checks, Check("false alarms, law that may never happen",
                                              False, said)),
                   timings={**low.timings, "informed": high.seconds})
