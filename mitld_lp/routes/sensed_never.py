"""False alarms with an event law that may never happen (``never > 0``), bracketed on
the ``sensed`` route instead of refused.

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
reports' information, not read); ``Result.width["information"]`` is that gap."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import replace
from types import MappingProxyType
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.problem import Posed, Route
from mitld_lp.result import Result
from mitld_lp.sensing.sensors import Sensor
from mitld_lp.solvers.rounding import one_minus

__all__ = ["never_alarms", "blind_model", "informed_model", "informed_detect",
           "solve_never"]

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


def informed_model(model: Any) -> Any:
    """``model`` with each sensor of :func:`never_alarms` replaced by the sensor without
    false alarms at least as informative (module docs)."""
    return _with(model, never_alarms(model),
                 lambda s: Sensor(informed_detect(s.detect, s.false_alarm), 0.0, s.delay))


def solve_never(posed: Posed, low: Result, routes: Sequence[Route]) -> Result:
    """The bracket of ``posed`` (module docs) from ``low``, the blind end solved (the
    route built its product with these sensors blind, their reports dropped by the
    controller: ``Belief.ignored``), and
    the informed problem solved here on the first of ``routes`` that claims it (the
    caller's: the ``sensed`` route, or the plain one where every sensor left is
    perfect)."""
    from mitld_lp.problem import pose_on
    from mitld_lp.routes.stages import build_posed

    informed = informed_model(posed.model)
    settings = replace(posed.settings, progress=False)
    seen = pose_on(list(routes), informed, posed.problem.constraints,
                   then=posed.problem.then, settings=settings,
                   objective=posed.problem.objective)
    high = seen.route.solve(seen, build_posed(seen, progress=False))
    minimum = posed.minimise
    # max: the blind controller's lower, the informed optimum's upper; min: the informed
    # optimum's lower, the blind controller's upper
    lower = high.lower if minimum else low.lower
    upper = low.upper if minimum else high.upper
    lower = min(lower, upper)  # both bound the same optimum: only rounding can cross
    slack = max(low.upper - low.lower, high.upper - high.lower)
    gap = max(upper - lower - slack, 0.0)
    met = gap <= (0.0 if posed.settings.precision != posed.settings.precision
                  else posed.settings.precision * max(lower, 0.0))
    events = ", ".join(f"{a} (never {float(posed.model.distributions[a].never):.6g}, "
                       f"false_alarm {posed.model.sensors[a].false_alarm:g}, informed "
                       f"detect {informed_detect(posed.model.sensors[a].detect, posed.model.sensors[a].false_alarm):.6g})"  # noqa: E501
                       for a in never_alarms(posed.model))
    detail = (f"{events}: the controller ignores these reports (information horizon 0); "
              f"bracket [{lower:.7g}, {upper:.7g}] between it and a sensor without false "
              f"alarms at least as informative; " +
              ("the ends meet: the reports cannot change the optimum" if met else
               f"gap {gap:.3g} beyond the solves' own widths: the reports' information, "
               "not read (a law that may never happen keeps the belief moving for ever)"))
    check = Check("false alarms, law that may never happen", bool(met), detail)
    failed = tuple(Check(f"informed sensor: {c.name}", c.passed, c.detail)
                   for c in high.checks if not c.passed)
    checks = (*low.checks, *failed, check)
    log.info("false alarms with a law that may never happen: %s", detail)
    return replace(low, lower=lower, upper=upper, checks=checks,
                   certified=all(c.passed for c in checks),
                   status=low.status if low.status is high.status else
                   next(s for s in (low.status, high.status) if s.name != "OPTIMAL"),
                   complement=None if low.complement is None else one_minus(lower, upper),
                   width={**low.width, "total": upper - lower, "information": gap},
                   timings={**low.timings, "informed": high.seconds})
