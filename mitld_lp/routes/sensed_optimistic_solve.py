"""The solve of a sensed band read for its best law (:mod:`mitld_lp.routes.sensed_optimistic`
has the route and says what is solved): the candidates' best cases, the fully observed
cooperative optimum above them, the bracket read back for a minimum."""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

from mitld_lp.checks import Check
from mitld_lp.problem import Posed
from mitld_lp.report import bracket_text
from mitld_lp.result import Result
from mitld_lp.routes.sensed_band import (
    band_gap,
    band_result,
    end_laws,
    full_information,
    read_back,
    sensed_candidate,
    within_time,
)
from mitld_lp.routes.sensed_solve import SensedPart
from mitld_lp.routes.stages import Built

__all__ = ["SensedOptimisticPart", "SENSED_OPTIMISTIC", "solve_sensed_optimistic"]

log = logging.getLogger(__name__)

#: What such an answer says of its controller.
SENSED_OPTIMISTIC = (
    "the bands read for the robot's best law (Pmaxmax) with sensors that miss events: the "
    "bracket is the best case over the bands of a controller that acts on observations; "
    "the controller reaches lower only when the events follow the law nature chose (its "
    "chain: export --chain), and guarantees nothing under a law of nature's choosing "
    "(bands 'worst' gives the guarantee)")


@dataclass(frozen=True, slots=True, eq=False)
class SensedOptimisticPart(SensedPart):
    """The sensed route's part with a band read for its best law: the chosen candidate's
    models, its best case (``best``: a
    :class:`~mitld_lp.running.sensed_optimistic_chain.BestCase`) on its interval
    ``chain``, each candidate's ``lower`` (``tried``), the fully observed cooperative
    optimum's ``upper`` (``full_upper``) and what the bracket is (``message``)."""

    best: Any = None
    chain: Any = None
    chosen_at: str = "middle law"
    tried: Mapping[str, float] | None = None
    full_upper: float = float("nan")
    message: str = ""
    reading: str = "best"
    band_best = True

    def summary(self, result: Result) -> dict[str, Any]:
        """The sensed route's keys, the band's best case (``band_best``) and the
        message."""
        from mitld_lp.report import models_summary

        out = models_summary(result)
        b = self.best
        out["band_best"] = {"lower": result.lower, "chosen_at": self.chosen_at,
                            "candidates": dict(self.tried or {}),
                            "full_information_upper": self.full_upper,
                            "chain_states": b.n_states if b is not None else None}
        out["message"] = self.message
        return out


def solve_sensed_optimistic(posed: Posed, built: Built) -> Result:
    """Solve a problem with sensed events and a band read for its best law (module docs)
    on its built information-state product (the middle law's beliefs), and at the
    bands' ends."""
    from mitld_lp.running.sensed_optimistic_chain import best_case

    t0 = time.perf_counter()
    s, limit = posed.settings, posed.settings.time_limit
    point, chain = sensed_candidate(posed, built, None)
    bands = {e: str(c.distribution) for e, c in sorted(point.sta.clocks.items())
             if c.distribution.is_ambiguous}
    if chain is None:  # no controller: the point answer's status says why
        return replace(point, bands=bands)
    timed = within_time(posed, t0, limit, "the fully observed cooperative optimum")
    full_upper, full_failed = (float("nan"), ()) if timed is None else full_information(timed)
    upper = min(u for u in (full_upper, 1.0) if u == u)
    chosen = (point, chain, best_case(chain), "middle law")
    tried = {"middle law": float(chosen[2].lower)}
    for label, laws in end_laws(posed.model.distributions):
        if upper - chosen[2].lower <= s.precision * max(chosen[2].lower, 0.0):
            break  # closed already: no other law's controller does better
        timed = within_time(posed, t0, limit, label)
        if timed is None:
            continue
        other, other_chain = sensed_candidate(timed, None, laws)
        if other_chain is None:  # no controller there (a time limit): not a candidate
            continue
        b = best_case(other_chain)
        tried[label] = float(b.lower)
        if b.lower > chosen[2].lower:
            chosen = (other, other_chain, b, label)
    point, chain, best, name = chosen
    upper, lower, width, cut, agree, closed = band_gap(best, (full_upper,), s.precision)
    won = best.truncated_won
    terms = "the complement's " if point.complemented else ""
    said = ", ".join(f"{k} {v!r}" for k, v in tried.items())
    detail = (f"{terms}lower {lower!r}: the best case over the band of the sensed optimum "
              f"at the {name} on its chain ({best.n_states} states, {best.iterations} "
              f"iterations, last change {best.last_change:.1e}; candidates: {said}); "
              f"{terms}upper {upper!r}: the fully observed cooperative optimum's "
              f"({full_upper!r}); gap {width:.3g}, of which {cut:.3g} the truncation's (runs "
              f"past a truncation point counted won, the best case is {won!r}); the rest "
              + ("within" if closed else "beyond") + f" the precision {s.precision:g}"
              + ("" if agree else f"; the chain's best case {best.lower!r} is above upper"))
    solver = float(point.width.get("solver", 0.0))
    widths = {"total": width, "solver": min(solver, width), "truncation": cut,
              "band": max(width - cut - solver, 0.0)}
    checks = (*point.checks, *full_failed, Check("best case over the band", closed, detail))
    bracket, complement = read_back(point, lower, upper)
    gap = ("" if closed else
           f"; not certified: the optimum over observation-based controllers of the best "
           f"case over the band is in [{bracket[0]!r}, {bracket[1]!r}] (gap {width:.3g}); "
           f"both ends sound")
    part = SensedOptimisticPart(point.part.lower_model, point.part.upper_model,
                                point.part.sensors, point.part.belief, best=best,
                                chain=chain, chosen_at=name, tried=tried,
                                full_upper=full_upper, message=SENSED_OPTIMISTIC + gap)
    result = band_result(posed, point, bracket, complement, checks, bands, part, widths, t0)
    log.info("sensed synthesis, the band's best law: %s, certified=%s",
             bracket_text(result.lower, result.upper), result.certified)
    return result
