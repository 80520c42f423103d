"""The trade-off curve: the best (constrained) success probability against a bound on a
second quantity (expected steps, expected cost, or the probability of a formula).

Each point is a constrained synthesis (:func:`mitld_lp.synthesis.synthesize_constrained`)
with the bound as one more constraint, on the route the model's features choose (with a
camera and a band: the worst case's or, ``bands = "best"``, the best law's), so each
comes with its certificate; the curve is drawn from the certified points only.  A point
whose synthesis finds no policy meeting its bound (a band's worst case, ``failed``) after
a point whose policy met a tighter one is that policy's value, not certified
(:func:`_carried`).
"""

from __future__ import annotations

import csv
import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mitld_lp.files import write as files
from mitld_lp.logic.constraints import (
    Constraint,
    ConstraintError,
    parse_constraint,
    parse_constraints,
)
from mitld_lp.model import Model
from mitld_lp.problem import ProblemError
from mitld_lp.routes.constrained import rows_for
from mitld_lp.solvers.constrained import OPTIMAL, optimise
from mitld_lp.solvers.constrained_model import Quantity
from mitld_lp.solvers.result import Status
from mitld_lp.synthesis import synthesize_constrained
from mitld_lp.util.progress import tracked

__all__ = ["ParetoPoint", "pareto", "write_csv", "plot"]

log = logging.getLogger(__name__)

_COLUMNS = ("bound", "probability_lower", "probability_upper", "achieved", "status",
            "certified")


@dataclass(frozen=True, slots=True)
class ParetoPoint:
    """One point: the bound on the second quantity, the certified bracket on the best
    success probability under it, and the second quantity's exact value on the policy."""

    bound: float
    lower: float
    upper: float
    achieved: float
    status: str
    certified: bool


def against_constraint(against: str, bound: float) -> Constraint:
    """``steps`` / ``cost`` / ``P(FORMULA)`` as the constraint ``... <= bound``; a
    probability's bound held at 1 (the curve's slack past its range's top, whose value may
    be 1, would otherwise pose a bound no probability bound may have)."""
    if against in ("steps", "cost"):
        return Constraint(against, "<=", bound, None, f"E({against}) <= {bound!r}")
    bound = min(bound, 1.0)
    text = f"{against} <= {bound!r}"
    c = parse_constraint(text, "--against")
    if c.kind != "prob":
        raise ConstraintError(f"--against: expected steps, cost or P(FORMULA), got {against!r}")
    return c


def _range(model: Model, against: str, options: dict[str, Any]) -> tuple[float, float]:
    """The bounds worth tracing: from the least value of the quantity any policy (meeting
    the model's constraints) achieves to its value on the fastest optimal policy."""
    lo_c = against_constraint(against, 1.0 if against.startswith("P") else 0.0)
    base = synthesize_constrained(model, [], then="min-cost" if against == "cost" else
                                  "min-steps" if against == "steps" else None, **options)
    if base.status != OPTIMAL:
        raise ConstraintError(f"the model's own constraints are {base.status}")
    if lo_c.kind == "prob":
        # P(phi) <= 1: phi joins the product
        probe = synthesize_constrained(model, [lo_c], **options)
        assert probe.status == OPTIMAL
        own = sum(1 for t in model.constraints if t.lstrip().startswith("P"))
        rows = rows_for(parse_constraints(model.constraints), "lower")
        least = optimise(probe.merged, Quantity("prob", own + 1, 1.0), False, rows)
        top = probe.constraints[-1].value
        return float(least.objective), float(top)
    from mitld_lp.routes.constrained import cost_vector
    costs = cost_vector(base.mdp, dict(model.costs))
    own = rows_for(parse_constraints(model.constraints), "lower")
    least = optimise(base.merged, Quantity(lo_c.kind), False, own, costs=costs)
    return float(least.objective), float(base.secondary or 0.0)


#: Times a point's bound is loosened when the policy misses it (or the model's bounds).
LOOSEN_ROUNDS = 4


def pareto(model: Model, against: str, points: int = 11, **options: Any) -> list[ParetoPoint]:
    """``points`` certified points, bounds evenly spaced over the range worth tracing.
    ``options``: :func:`mitld_lp.synthesis.synthesize`'s settings, used for every point
    (each honoured or refused by name: :func:`mitld_lp.synthesis.pose`)."""
    if "then" in options or "constraints" in options:
        raise ProblemError("pareto: the curve poses its own constraint on each point (and "
                           "its own then for --against steps/cost); give the model's "
                           "constraints in its file, not as options")
    lo, hi = _range(model, against, options)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ConstraintError(f"--against {against}: no finite range ({lo}, {hi})")
    out: list[ParetoPoint] = []
    held: ParetoPoint | None = None  # the last point whose policy meets its bound
    for b in tracked(np.linspace(lo, max(hi, lo), points), options.get("progress"),
                     total=points, desc="pareto", unit=" points", leave=False):
        c = against_constraint(against, float(b) + 1e-9)
        r = synthesize_constrained(model, [c], **options)
        loosen = 0.0
        for _ in range(LOOSEN_ROUNDS):
            misses = [v.miss for v in r.constraints if math.isfinite(v.miss)]
            if r.status != OPTIMAL or not any(m > 0 for m in misses):
                break
            # the range's ends are LP optima, exact only to the LP's tolerance: no policy
            # may meet such a bound in exact arithmetic (a constraint holds only when its
            # certified bound meets it, docs/constraints.md), nor, at the corner, the
            # model's own bounds with it; this point's bound is loosened until one does
            loosen = max(2.0 * max(misses), 10.0 * loosen)
            c = against_constraint(against, float(b) + 1e-9 + loosen)
            r = synthesize_constrained(model, [c], **options)
        achieved = r.constraints[-1].value if r.constraints else float("nan")
        point = ParetoPoint(float(c.bound), r.lower, r.upper, achieved, r.status,
                            r.certified)
        if r.status == OPTIMAL and all(v.holds for v in r.constraints):
            held = point
        elif held is not None and r.status != Status.INFEASIBLE:
            point = _carried(held, point)
        out.append(point)
    return out


def _carried(held: ParetoPoint, failed: ParetoPoint) -> ParetoPoint:
    """A point whose synthesis found no policy meeting its bound (a band's worst case:
    no candidate meets it under every law, status ``failed``), after one whose policy
    met a tighter bound: that policy meets this looser one too, so its task value is a
    lower bound here; the upper bound is this point's own (NaN: 1).  Not certified."""
    upper = failed.upper if failed.upper == failed.upper else 1.0
    log.info("pareto: no policy found for the bound %r; the policy of the bound %r "
             "meets it (its value %r a lower bound)", failed.bound, held.bound, held.lower)
    return ParetoPoint(failed.bound, held.lower, max(upper, held.lower), held.achieved,
                       held.status, False)


def write_csv(points: list[ParetoPoint], path: Path, *, overwrite: bool = False) -> Path:
    """The points as CSV (:data:`_COLUMNS`), under the output-file rule."""
    out = files.writable_path(path, overwrite=overwrite, suffixes=(".csv",))
    with files.replacing(out, newline="") as fh:
        w = csv.writer(fh)
        w.writerow(_COLUMNS)
        for p in points:
            w.writerow([repr(p.bound), repr(p.lower), repr(p.upper), repr(p.achieved), p.status,
                        p.certified])
    return out


def plot(points: list[ParetoPoint], path: Path, against: str, title: str, *,
         overwrite: bool = False) -> int:
    """Draw the certified points (the bracket as a band) as a PNG, under the output-file
    rule; returns how many were left out."""
    files.writable_path(path, overwrite=overwrite, suffixes=(".png",))  # before drawing
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    good = [p for p in points if p.certified]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    if good:
        x = [p.bound for p in good]
        ax.fill_between(x, [p.lower for p in good], [p.upper for p in good], alpha=0.3,
                        label="certified bracket")
        ax.plot(x, [p.lower for p in good], "o-", label="achieved (lower)")
    ax.set_xlabel(f"bound on {'E(' + against + ')' if against in ('steps', 'cost') else against}")
    ax.set_ylabel("success probability")
    ax.set_title(title)
    if good:  # no certified point: nothing to label
        ax.legend(loc="lower right")
    fig.tight_layout()
    try:
        files.write_figure(fig, path, overwrite=overwrite, suffixes=(".png",), dpi=120)
    finally:
        plt.close(fig)
    return len(points) - len(good)
