"""The bracket of a task with a safety part seen through sensors, with constraints or
``then``, where end components of information states hold persistent hypotheses but
no keep state (:mod:`mitld_lp.routes.sensed_constrained`): some hypothesis is safe in
one state and open in another, or (with ``then`` or a bound on steps or costs) open
hypotheses would take steps for ever.

Two constrained LPs are solved on the information-state product.  The *exact end*
keeps the task only at keep states (:class:`mitld_lp.running.sensed_joint.Keeps`:
playing their end component for ever keeps the true run's task exactly when its
hypothesis is persistent there), and a stay, which wins no open hypothesis, elsewhere:
its policy is the answer's, its certified value ``lower`` (for a minimum, ``upper`` read
back), each constraint met by it in exact arithmetic.  The *relaxed end* also credits
every other state of an end component of states with some persistent hypothesis with
a keep worth the weight of its persistent hypotheses (at least what the hypotheses
persistent throughout any end component through it are worth; a run staying in an end
component through a state with none loses the task) and its constraints as they are: a
relaxation of every observation-based policy, whose weak-duality bound is the answer's
``upper`` (for a minimum, ``lower``).  Their distance is reported as the width's
``observation`` part (beside the truncation's), the check ``observation-based
acceptance`` says ``bracketed``; the precision check holds the solver's part only, as
for the truncation.  Infeasibility is proved only where the relaxed end is infeasible
too; else the answer is ``failed``, saying so.
"""

from __future__ import annotations

from dataclasses import replace

from mitld_lp.checks import Check
from mitld_lp.result import Result, precision_check
from mitld_lp.solvers.result import Status

__all__ = ["bracketed"]


def bracketed(exact: Result, relaxed: Result, mixed: int, minimise: bool,
              precision: float) -> Result:
    """The answer from the exact end's ``exact`` and the relaxed end's ``relaxed``
    (module docs); ``mixed``: the number of states the relaxed end credits."""
    said = (f"bracketed: {mixed} information states in end components that keep some "
            "hypotheses persistent and not others; the policy keeps the task only where "
            "no hypothesis is open, the other bound credits each such state with "
            "its persistent hypotheses")
    if not exact.status.has_solution:
        if relaxed.status == Status.INFEASIBLE or exact.status != Status.INFEASIBLE:
            return exact
        message = ("no policy keeping the task only where no hypothesis is open "
                   "meets the constraints; infeasibility is not proved (the model crediting "
                   f"the other persistent hypotheses is feasible): {said}")
        return replace(exact, status=Status.FAILED,
                       part=replace(exact.part, message=message))
    ok = relaxed.status.has_solution
    nan = float("nan")
    if minimise:  # read back: the exact end gives upper, the relaxed one lower
        lower, upper = (relaxed.lower if ok else nan), exact.upper
        complement = (exact.complement[0], relaxed.complement[1] if ok else nan) \
            if exact.complement is not None and relaxed.complement is not None else None
    else:
        lower, upper, complement = exact.lower, (relaxed.upper if ok else nan), None
    width = dict(exact.width)
    total = upper - lower
    gap = max(total - float(width.get("total", 0.0)), 0.0) if ok else nan
    width.update(total=total, observation=gap)
    solver = float(width.get("solver", 0.0))
    checks = [c for c in exact.checks if c.name != "precision"]
    checks.append(Check("observation-based acceptance", ok,
                        said if ok else f"the relaxed LP is {relaxed.status}"))
    checks.append(precision_check(lower, upper, solver,
                                  float(width.get("truncation", 0.0)) + gap, precision))
    return replace(exact, lower=lower, upper=upper, complement=complement, width=width,
                   checks=tuple(checks), certified=all(c.passed for c in checks),
                   timings={**exact.timings, "solve": max(  # both count from one start
                       exact.timings.get("solve", 0.0), relaxed.timings.get("solve", 0.0))})
