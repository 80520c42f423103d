"""Sensed events whose law is known only within a band (the ``sensed`` route with a band):
the worst case over the band for a policy that acts on observations, certified where the
bracket closes, honest about the gap where it does not.

The policy: the sensed optimum (:mod:`mitld_lp.routes.sensed_solve`) at a law of the
band, the best by its worst case of three: the band's nominal law (the centre of an
interval parameter, the fitted law of a fit; the law the robust constrained route
chooses at too), every band at its low end, every band at its high end (an interval
parameter's ends, :func:`end_laws`).  A sensor with false alarms (a band whose laws
surely happen) changes no step: each candidate is the point-law optimum with false
alarms, and its chain draws every step's report (:mod:`mitld_lp.running.sensed_chain`).

``lower``: the chosen controller's worst case over the band, with the band's semantics
of the robust route (docs/robust.md: at every step nature, who has seen everything,
picks each pending band event's hazard inside its band at the true clock): its chain
over the truth and the controller's memory with nature's corners as choices
(:mod:`mitld_lp.running.sensed_band_chain`), evaluated by value iteration from below
(sound at every iterate).  ``export --chain`` writes that chain; Storm's robust check of
it gives ``lower``.

``upper``: the least of sound upper bounds on the optimum over observation-based
policies of the worst case: the sensed optimum's ``upper`` at each of those laws (nature
may play that law at every step) and the fully observed robust optimum's ``upper``
(:mod:`mitld_lp.routes.robust`; an observation-based policy is a full-information one).
The answer is certified when ``upper - lower``, less the truncation's part of it, is
within the precision (relative to ``lower``, as every route's) and both solves
certified; otherwise the check ``worst case over the band`` says the gap, both ends
still sound.  The truncation's part (reported apart in ``width``, as every route reports
it): the controller's worst case with the runs past a truncation point counted won (the
upper bounds' reading) above ``lower``.

``objective = "min"``: as on the robust route, the complement is maximised (the sensed
route builds the complement's automaton under a band; nature then makes the task as
likely as it can) and each bound read back: ``upper`` is the returned controller's worst
case, ``lower`` the sound bound, ``complement`` the complement's bracket; the exported
chain is the complement's, Storm's robust check of it gives ``1 - upper``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.problem import Posed
from mitld_lp.report import bracket_text
from mitld_lp.result import Result
from mitld_lp.routes.sensed_solve import SensedPart, solve_sensed
from mitld_lp.routes.stages import Built
from mitld_lp.solvers.certify import float_up
from mitld_lp.solvers.rounding import one_minus

__all__ = ["SensedBandPart", "band_gap", "band_result", "blind_at", "end_laws",
           "full_information", "read_back", "sensed_candidate", "solved_bracket",
           "solve_sensed_band", "within_time"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, eq=False)
class SensedBandPart(SensedPart):
    """The sensed route's part with a band: the point answer's models (at the nominal
    law), and the band's bounds: ``worst`` the controller's worst case on its chain
    (:class:`~mitld_lp.running.sensed_band_chain.SensedBandValue`), ``nominal_upper``
    the sensed optimum's upper bound at the nominal law, ``full_upper`` the fully
    observed robust optimum's, ``message`` what the bracket is."""

    worst: Any = field(default=None)
    nominal_upper: float = float("nan")
    point_uppers: Mapping[str, float] = field(default_factory=dict)
    chosen_at: str = "middle law"
    full_upper: float = float("nan")
    message: str = ""
    band_worst = True

    def summary(self, result: Result) -> dict[str, Any]:
        """The sensed route's keys, the band's bounds (``band_worst``) and, when the
        bracket does not close, the message that says its gap."""
        from mitld_lp.report import models_summary

        out = models_summary(result)
        w = self.worst
        out["band_worst"] = {"lower": result.lower, "chosen_at": self.chosen_at,
                             "sensed_uppers": dict(self.point_uppers),
                             "full_information_upper": self.full_upper,
                             "chain_states": w.n_states if w is not None else None}
        if self.message:
            out["message"] = self.message
        return out


def full_information(posed: Posed) -> tuple[float, tuple[Check, ...]]:
    """The fully observed robust optimum's ``upper`` for the same problem (its sensors
    read as perfect), with the bands read as ``posed``'s settings read them (the worst
    law, or with ``bands = "best"`` the cooperative optimum): a sound upper bound for
    every observation-based policy; NaN, with the reason, where the robust route does
    not give it (its budget, a refusal)."""
    from mitld_lp.distributions import DistributionError
    from mitld_lp.problem import ProblemError, pose_on
    from mitld_lp.routes.robust import RobustRoute
    from mitld_lp.routes.stages import build_posed
    from mitld_lp.util.memory import ProductTooLarge

    model = dataclasses.replace(posed.model, sensors=MappingProxyType({}))
    settings = replace(posed.settings, progress=False)
    try:  # the robust route itself (the package's route list would lead back here)
        seen = pose_on([RobustRoute()], model, settings=settings,
                       objective=posed.problem.objective)
        full = seen.route.solve(seen, build_posed(seen, progress=False))
    except (ProblemError, ProductTooLarge, DistributionError) as exc:
        # a budget, a refusal, or a band the robust route cannot truncate (one whose
        # laws may never happen: its upper survival stays above the share): the other
        # bounds
        log.info("fully observed robust bound not used: %s", exc)
        return float("nan"), ()
    failed = tuple(c for c in full.checks if not c.passed)
    return (solved_bracket(full)[1] if full.controller is not None else float("nan")), failed


def end_laws(distributions: Mapping[str, Any]) -> list[tuple[str, dict[str, Any]]]:
    """The laws of the band to try the sensed optimum at besides its middle law: every
    band at its low end, and every band at its high end (an interval parameter's ends;
    a band with no end laws keeps its middle law), each as the band with that point law
    (its hazard intervals unchanged)."""
    from mitld_lp.distributions import from_table
    from mitld_lp.distributions.band import ConstantBand, EnvelopeBand

    out = []
    for end, name in ((0, "low ends"), (-1, "high ends")):
        laws, moved = dict(distributions), False
        for e, d in distributions.items():
            try:
                if isinstance(d, ConstantBand) and 0.0 < (d.lo, d.hi)[end] <= 1.0:
                    law = from_table({"geometric": (d.lo, d.hi)[end]}, d.label)
                elif isinstance(d, EnvelopeBand) and len(d.laws) > 1:
                    law = d.laws[1:][end]
                else:
                    continue
            except ValueError:  # an end no point law of its own can take
                continue
            laws[e], moved = dataclasses.replace(d, nominal=law), True
        if moved:
            out.append((name, laws))
    return out


def blind_at(posed: Posed, laws: Mapping[str, Any]) -> list[str]:
    """The sensed events with false alarms whose candidate at the band's point law
    ``laws`` is built blind (that law may never happen, :mod:`mitld_lp.routes.
    sensed_never`) while the posed band's middle law surely happens (a band of such
    laws beside one that surely happens, whose hazard may stay positive for ever):
    that candidate's controller drops their reports, a controller like any other, but
    its upper bound is the blind optimum's, no bound on a controller reading them, so
    it is not used."""
    from mitld_lp.routes.sensed_never import never_alarms

    model = dataclasses.replace(posed.model, distributions=MappingProxyType(dict(laws)))
    return sorted(set(never_alarms(model)) - set(never_alarms(posed.model)))


def _candidate(posed: Posed, built: Built | None, laws: Mapping[str, Any] | None
               ) -> tuple[Result, Any]:
    """The sensed optimum with the band's point law ``laws`` (None: the middle law, on
    ``built``) and its controller's worst case over the band."""
    from mitld_lp.running.sensed_band_chain import worst_case

    point, chain = sensed_candidate(posed, built, laws)
    return point, None if chain is None else worst_case(chain)


def sensed_candidate(posed: Posed, built: Built | None, laws: Mapping[str, Any] | None
                     ) -> tuple[Result, Any]:
    """The sensed optimum with the band's point law ``laws`` (None: the middle law, on
    ``built``; else on the product the posed route builds at that law: the reacting one
    on route ``sensed-reacting``) and its controller's interval chain over the band
    (:func:`~mitld_lp.running.sensed_band_chain.sensed_band_chain_of`; None without a
    controller), its size checked against ``max_states`` before it is unfolded."""
    from mitld_lp.running.sensed_band_chain import chain_floor, sensed_band_chain_of
    from mitld_lp.util.memory import ProductTooLarge

    if laws is not None:
        model = dataclasses.replace(posed.model, distributions=MappingProxyType(laws))
        posed = replace(posed, problem=replace(posed.problem, model=model))
        built = posed.route.build(posed, progress=posed.settings.progress)
    assert built is not None
    point = solve_sensed(posed, built)
    if point.controller is None:
        return point, None
    budget = posed.settings.max_states
    floor, reached = chain_floor(point.mdp, point.part.lower_model.policy, point.dta)
    if budget is not None and floor > budget:  # before the unfolding, from the product
        raise ProductTooLarge(
            f"the sensed controller's interval chain has at least {floor:,} states (the "
            f"hypotheses of the {reached:,} information states it reaches, each a truth "
            f"the chain holds), more than {budget:,} (max_states); raise max_states, "
            "loosen epsilon, or shrink the model")
    return point, sensed_band_chain_of(point, max_states=budget, reading=posed.settings.bands)


def within_time(posed: Posed, t0: float, limit: float | None, what: str) -> Posed | None:
    """``posed`` with the time left of ``limit`` seconds from ``t0`` (None: none left,
    ``what`` is not solved and its bound not used)."""
    if limit is None:
        return posed
    left = t0 + limit - time.perf_counter()
    if left <= 0.001:
        log.info("time limit: %s not tried", what)
        return None
    return replace(posed, settings=replace(posed.settings, time_limit=left))


def solved_bracket(r: Result) -> tuple[float, float]:
    """``r``'s bracket in the solved automaton's terms: the complement's for a minimum
    read back from it (every minimum with a band, as on the robust route)."""
    if r.complemented:
        return r.complement if r.complement is not None else (1.0 - r.upper, 1.0 - r.lower)
    return r.lower, r.upper


def band_gap(worst: Any, uppers: tuple[float, ...], precision: float
             ) -> tuple[float, float, float, float, bool, bool]:
    """The bracket of the controller's worst case ``worst`` (or its best case, read the
    same: a ``lower`` and a ``truncated_won``) under the least of the sound
    upper bounds ``uppers`` (NaN: not given): ``upper``, ``lower``, the width, the
    truncation's part of it (the controller's worst case with the runs past a truncation
    point counted won, the upper bounds' reading, above its lower: reported apart, as
    every route reports it), whether the chain agrees with the bounds (its worst case
    above a sound upper bound would mean they disagree; none is expected) and whether
    the rest of the gap, the band's, is within ``precision`` relative to ``lower``."""
    upper = min(u for u in (*uppers, 1.0) if u == u)
    lower = float(min(worst.lower, upper))
    width = upper - lower
    agree = worst.lower <= upper + precision * max(upper, 0.0)
    won = worst.truncated_won
    cut = float(min(max(won - lower, 0.0), width)) if won == won else 0.0
    return upper, lower, width, cut, agree, agree and width - cut <= precision * max(lower, 0.0)


def read_back(point: Result, lower: float, upper: float
              ) -> tuple[tuple[float, float], tuple[float, float] | None]:
    """The bracket ``[lower, upper]`` of the solved automaton (``upper`` rounded up) as
    the task's, and the complement's bracket (None unless ``point`` solved a minimum as
    its complement's maximum: then ``Pmin(task) = 1 - Pmax(not task)``)."""
    bracket: tuple[float, float] = (lower, float_up(upper))
    if point.complemented:
        return one_minus(*bracket), bracket
    return bracket, None


def band_result(posed: Posed, point: Result, bracket: tuple[float, float],
                complement: tuple[float, float] | None, checks: tuple[Check, ...],
                bands: dict[str, str], part: Any, widths: dict[str, float], t0: float
                ) -> Result:
    """``point`` (the chosen candidate's sensed answer) with the band's bracket, checks,
    part and widths, on ``posed``'s model (its band); the band's time from ``t0``."""
    return replace(point, model=posed.model, lower=bracket[0], upper=bracket[1],
                   value=bracket[1] if point.complemented else bracket[0],
                   complement=complement, certified=all(c.passed for c in checks),
                   checks=checks, bands=bands, part=part, width=widths,
                   timings={**point.timings, "band": time.perf_counter() - t0})


def solve_sensed_band(posed: Posed, built: Built) -> Result:
    """Solve a problem with sensed events and a band (module docs) on its built
    information-state product (the middle law's beliefs), and at the bands' ends.  A
    minimum is its complement's maximum (the sensed route builds the complement's
    automaton under a band), each bound read back: ``upper`` the controller's worst case
    (the most probable the task is under some law), ``lower`` the sound bound."""
    t0 = time.perf_counter()
    point, worst = _candidate(posed, built, None)
    bands = {e: str(c.distribution) for e, c in sorted(point.sta.clocks.items())
             if c.distribution.is_ambiguous}
    if worst is None:  # no controller: the point answer's status says why
        return replace(point, bands=bands)
    uppers = {"middle law": solved_bracket(point)[1]}
    chosen, name = (point, worst), "middle law"
    limit, s = posed.settings.time_limit, posed.settings
    timed = within_time(posed, t0, limit, "the fully observed robust optimum")
    full_upper, full_failed = (float("nan"), ()) if timed is None else full_information(timed)
    for label, laws in end_laws(posed.model.distributions):
        _, lower_now, width_now = band_gap(chosen[1], (*uppers.values(), full_upper),
                                               s.precision)[:3]
        if width_now <= s.precision * max(lower_now, 0.0):
            break  # closed already, truncation too: no other law's controller does better
        timed = within_time(posed, t0, limit, label)
        if timed is None:
            continue
        other, w = _candidate(timed, None, laws)
        if w is None:  # no controller there (a time limit): its bound is not used
            continue
        blind = blind_at(posed, laws)
        if blind:
            log.info("the sensed optimum at the band's %s is built with %s blind (its law "
                     "may never happen): its upper bound is not used", label, ", ".join(blind))
        else:
            uppers[label] = solved_bracket(other)[1]
        if w.lower > chosen[1].lower:
            chosen, name = (other, w), label
    point, worst = chosen
    upper, lower, width, cut, agree, closed = band_gap(worst, (*uppers.values(), full_upper),
                                                   s.precision)
    said = ", ".join(f"{k} {v!r}" for k, v in uppers.items())
    terms = "the complement's " if point.complemented else ""
    detail = (f"{terms}lower {lower!r}: the worst case over the band of the sensed optimum "
              f"at the {name} on its chain ({worst.n_states} states, {worst.iterations} "
              f"iterations, last change {worst.last_change:.1e}); {terms}upper {upper!r}: "
              f"the least of the sensed optima's upper bounds ({said}) and the fully "
              f"observed robust optimum's ({full_upper!r}); gap {width:.3g}, of which "
              f"{cut:.3g} the truncation's (runs past a truncation point counted won, the "
              f"worst case is {worst.truncated_won!r}); the rest "
              + ("within" if closed else "beyond") + f" the precision {s.precision:g}"
              + ("" if agree else f"; the chain's worst case {worst.lower!r} is above upper"))
    solver = float(point.width.get("solver", 0.0))
    widths = {"total": width, "solver": solver, "truncation": cut,
              "band": max(width - cut - solver, 0.0)}
    check = Check("worst case over the band", closed, detail)
    checks = (*point.checks, *full_failed, check)
    bracket, complement = read_back(point, lower, upper)
    what = ("the most probable the task is under some law of the band"
            if point.complemented else "what the returned controller guarantees under "
            "every law of the band")
    message = ("" if closed else
               f"not certified: the worst case over the band of an observation-based "
               f"controller is in [{bracket[0]!r}, {bracket[1]!r}] (gap {width:.3g}); both "
               f"ends sound: {'upper' if point.complemented else 'lower'} is {what}")
    part = SensedBandPart(point.part.lower_model, point.part.upper_model,
                          point.part.sensors, point.part.belief, worst=worst,
                          nominal_upper=uppers["middle law"], point_uppers=uppers,
                          chosen_at=name, full_upper=full_upper, message=message)
    result = band_result(posed, point, bracket, complement, checks, bands, part, widths, t0)
    log.info("sensed synthesis over the band: %s, certified=%s",
             bracket_text(result.lower, result.upper), result.certified)
    return result
