"""A band whose hazard may stay positive for ever while its laws' never masses differ
(a Poisson law beside a table of masses leaving some mass to never): no truncation of it
is sound (:class:`~mitld_lp.distributions.band.UnboundedBand`), so the fully observed
band routes bracket it instead (docs/robust.md, "The tail of a band").

Past a step ``K`` (:func:`~mitld_lp.distributions.band.tail_step`) the band is replaced
by a constant interval twice (:func:`~mitld_lp.distributions.band.tail_bands`): the
*outer* one holds every interval of the band past ``K`` (nature may do more than it
can), the *inner* one lies within every one (nature may do less).  Both are constant
from ``K + 1``, so the route solves each exactly, nothing truncated.

* Worst law (``Settings.bands = "worst"``): the policy solved on the outer band
  guarantees on the true band at least its worst case there (every choice of nature's
  within the true band is one within the outer band): the policy's end of the bracket
  (``lower`` of a maximum, ``upper`` of a minimum), its constraints met under every law
  of the true band.  The inner band's optimum bounds the true optimum from the other
  side (nature has fewer choices there).
* Best law (``"best"``): the other way round: the inner band's policy reaches its value
  at a law within the true band; the outer band's optimum bounds the true one.
* Where no constant interval lies within every interval of the band past ``K`` the
  optimum's end is solved on the band truncated at ``K + 1`` instead, a run still
  waiting for the event there counted as won for the upper bound and lost for the lower
  one (the route's two truncation models), and the answer says so.

The route's answer is the policy side's (its controller, product and exports: the
interval chain exported is the one its end was computed on), with the other end taken
from the other solve; the check ``band's tail past step K`` passes where the two ends
meet within ``epsilon`` (beyond each solve's own precision), else it names the gap and
the answer is not certified.  A constrained problem found infeasible is reported so
only where the optimum's side, whose laws all lie in the true band, finds it.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.distributions.band import needs_tail, tail_bands, tail_intervals, tail_step
from mitld_lp.problem import Posed
from mitld_lp.result import Result
from mitld_lp.solvers.result import Status

__all__ = ["Tail", "tail_of", "policy_side", "solve_tailed", "tailed_model"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Tail:
    """The events whose bands are bounded past a step: ``steps`` their ``K``,
    ``outer`` / ``inner`` their laws with the outer and the inner interval past it
    (an event absent from ``inner`` has none: it is truncated at ``K + 1`` there)."""

    steps: dict[str, int]
    outer: dict[str, FirstOccurrence]
    inner: dict[str, FirstOccurrence]
    said: str  # the intervals, for the check's detail

    def laws(self, which: str) -> dict[str, FirstOccurrence]:
        return self.outer if which == "outer" else self.inner


def tail_of(model: Any, epsilon: float, truncation: dict[str, int] | None) -> Tail | None:
    """The tail of ``model``'s bands that need one (:func:`needs_tail` at the share of
    ``epsilon`` each event's truncation would get; an event with an explicit
    ``truncation`` point is cut there as asked), or None."""
    laws = model.distributions
    share = epsilon / max(len(laws), 1)
    steps: dict[str, int] = {}
    outer: dict[str, FirstOccurrence] = {}
    inner: dict[str, FirstOccurrence] = {}
    said = []
    for a, law in sorted(laws.items()):
        if a in (truncation or {}) or not needs_tail(law, share):
            continue
        K = tail_step(law, share)
        o, i = tail_bands(law, K)
        steps[a], outer[a] = K, o
        (o_lo, o_hi), within = tail_intervals(law, K)
        if i is not None:
            inner[a] = i
        said.append(f"{a} ~ {law} past step {K}: outer [{o_lo:.6g}, {o_hi:.6g}], inner "
                    + ("none (truncated at step " + str(K + 1) + " instead)" if within is None
                       else f"[{within[0]:.6g}, {within[1]:.6g}]"))
    if not steps:
        return None
    return Tail(steps, outer, inner, "; ".join(said))


def tailed_model(model: Any, laws: dict[str, FirstOccurrence]) -> Any:
    """``model`` with the laws of ``laws`` in place of its own."""
    return dataclasses.replace(model, distributions=MappingProxyType(
        {**model.distributions, **laws}))


def _tail(posed: Posed) -> Tail | None:
    s = posed.settings
    eps = posed.model.epsilon if s.epsilon is None else s.epsilon
    return tail_of(posed.model, eps, s.truncation_map)


def _side(posed: Posed, tail: Tail, which: str) -> Posed:
    """``posed`` with the bands' tails ``which`` (outer or inner); an event without an
    inner interval is truncated at ``K + 1`` there (the route's truncation models)."""
    laws = tail.laws(which)
    cut = {a: K + 1 for a, K in tail.steps.items() if a not in laws}
    settings = posed.settings
    if cut:
        settings = replace(settings, truncation=tuple(sorted(
            {**(settings.truncation_map or {}), **cut}.items())))
    model = tailed_model(posed.model, laws)
    return replace(posed, problem=replace(posed.problem, model=model), settings=settings)


def _policy_which(posed: Posed) -> str:
    """The tail the policy is solved on: the outer one against the worst law (its
    guarantee holds on the true band), the inner one for the best (its law is one of the
    true band's)."""
    return "outer" if posed.settings.bands == "worst" else "inner"


def policy_side(posed: Posed) -> Posed:
    """The problem the route builds and its policy is solved on (``posed`` itself where
    no band needs a tail)."""
    tail = _tail(posed)
    return posed if tail is None else _side(posed, tail, _policy_which(posed))


def solve_tailed(route: Any, posed: Posed, built: Any,
                 solve: Callable[[Posed, Any], Result]) -> Result:
    """``solve`` on ``built`` (the route's build of :func:`policy_side`) and, where a
    band needs a tail, on the other side too, the two answers joined (module docs)."""
    tail = _tail(posed)
    if tail is None:
        return solve(posed, built)
    which = _policy_which(posed)
    other = "inner" if which == "outer" else "outer"
    pol = solve(_side(posed, tail, which), built)
    bound_posed = _side(posed, tail, other)
    log.info("a band's tail bounded (%s): the policy on the %s tail, the bound on the %s",
             tail.said, which, other)
    bound = solve(bound_posed, route.build(bound_posed, False))
    return _joined(posed, tail, pol, bound, which)


def _joined(posed: Posed, tail: Tail, pol: Result, bound: Result, which: str) -> Result:
    """The policy side's answer ``pol`` with the other end of the bracket from
    ``bound`` (module docs)."""
    maximum = posed.problem.objective == "max"
    named = tuple(Check(f"{'inner' if which == 'outer' else 'outer'} tail: {c.name}",
                        c.passed, c.detail) for c in bound.checks)
    steps = ", ".join(f"{a} past step {K}" for a, K in sorted(tail.steps.items()))
    if bound.status is Status.INFEASIBLE:
        # the worst law: no policy meets the constraints under every law of the inner
        # tail, all of them the band's; the best: none under any law of the outer tail,
        # which holds every law of the band
        return _noted(bound, f"infeasible on the band's {'inner' if which == 'outer' else 'outer'}"
                      f" tail ({steps}), so on the band too")
    if pol.status is not Status.OPTIMAL or pol.controller is None:
        # the policy side found none: feasibility unknown on the true band
        lower = float("nan") if maximum else bound.lower
        upper = bound.upper if maximum else float("nan")
        return _noted(replace(pol, lower=lower, upper=upper, status=Status.FAILED,
                              controller=None, certified=False,
                              checks=(*pol.checks, *named)),
                      f"no policy found on the band's {which} tail ({steps}): "
                      f"feasibility unknown; {pol.message}".rstrip("; "))
    lower, upper = (pol.lower, bound.upper) if maximum else (bound.lower, pol.upper)
    own = sum(max(float(r.upper) - float(r.lower), 0.0) for r in (pol, bound)
              if r.upper == r.upper and r.lower == r.lower)
    total = upper - lower
    gap = max(total - own, 0.0)
    eps = posed.model.epsilon if posed.settings.epsilon is None else posed.settings.epsilon
    tol = posed.settings.certify_tol
    met = bool(total == total and -tol <= total and gap <= eps + tol)
    check = Check(f"band's tail past step {', '.join(map(str, tail.steps.values()))}", met,
                  f"{tail.said}; the policy on the {which} tail, the other end on the "
                  f"other; the two ends {'meet' if met else 'do not meet'}: gap {gap:.3g} "
                  f"{'<=' if met else '>'} epsilon {eps:g} beyond the solves' own width "
                  f"{own:.3g}")
    checks = (*pol.checks, *named, check)
    width = {**pol.width, "total": total, "tail": gap}
    complement = (1.0 - upper, 1.0 - lower) if pol.complement is not None else None
    return _noted(replace(pol, lower=lower, upper=upper, checks=checks,
                          certified=all(c.passed for c in checks), width=width,
                          complement=complement),
                  f"the band's tail bounded ({steps}): gap {gap:.3g}")


def _noted(r: Result, note: str) -> Result:
    """``r`` with ``note`` added to its route's message (where its part has one)."""
    part = r.part
    if hasattr(part, "message") and dataclasses.is_dataclass(part):
        msg = getattr(part, "message", "") or ""
        part = replace(part, message=f"{msg}; {note}" if msg else note)  # type: ignore[type-var]
        return replace(r, part=part)
    return r
