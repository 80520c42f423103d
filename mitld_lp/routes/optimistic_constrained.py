"""Constraints or ``then`` with a band read for its best law (``Settings.bands = "best"``,
PRISM's ``Pmaxmax``, Storm's cooperative resolution): docs/robust.md, "Reading a band
optimistically".

Under the optimistic reading nature is on the robot's side, for the task *and* for the
constraints: the answer is the optimistic constrained optimum

    V+ = max { P_(pi, nu)(task) : (pi, nu) such that every constraint holds under (pi, nu) }

over pairs of a robot policy ``pi`` and a law ``nu`` of the bands, nature choosing at
every step, for each state and robot choice, the hazards of the band (as in the robust
route's ``Pmaxmax``, where nature's hazard may follow the robot's choice).  The pair is
one randomised policy of an ordinary MDP, the *cooperative MDP*: its choices are the
pairs (robot choice, vertex row of the choice's hazard box)
(:func:`cooperative_mdp`), and its constrained optimum is solved by the constrained LP
of the point laws (:func:`mitld_lp.routes.constrained.solve_merged`), its bracket
certified as theirs is.

A mixture of a choice's vertex rows is a law of the band when the choice has one band
event pending (the mixture of the rows at ``lo`` and ``hi`` is the row at a hazard
between them); with several pending together it is one exactly when its weights are
those of independent hazards (multilinear interpolation: a product of one weight per
event).  Every law of the band is such a mixture, so the LP's optimum bounds ``V+`` from
above whatever policy it chooses (``upper``).  The policy returned plays, at a choice
with several band events, the law of independent hazards with the same chance of each
event's upper hazard as the LP's mixture (:func:`independent_weights`; the LP's solution
mixes corners only where they tie, up to the solver's tolerance), and its task value
and constraints are evaluated again in exact arithmetic on that law: ``lower`` is its
task value, the constraints' values are its own.  If it breaks a constraint, ``lower``
is not claimed (NaN) and the status is ``failed``.

The answer is an optimistic value, not a guarantee: the robot's half of the policy
(the controller plays each pair's robot choice) reaches ``lower`` and meets the
constraints only when the events follow nature's half; under another law it may do
worse or break a constraint (its message says so).  Its controlled chain at nature's
chosen rows is a plain Markov chain (``export --chain``), on which Storm's
``P=? [F "accept"]`` is ``lower``.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from mitld_lp.checks import Check
from mitld_lp.mdp import MDP
from mitld_lp.problem import Posed
from mitld_lp.product.imdp import IntervalMDP, VertexRows, point_mdp, vertex_rows
from mitld_lp.result import Result, precision_check
from mitld_lp.routes.constrained import ConstrainedPart, solve_merged
from mitld_lp.routes.stages import Built
from mitld_lp.solvers.constrained_model import Merged, merge
from mitld_lp.solvers.result import Status

__all__ = ["OPTIMISTIC_CONSTRAINED", "OptimisticPart", "cooperative_mdp",
           "independent_weights", "at_law", "solve_optimistic_constrained"]

#: What an optimistic answer with constraints says of its controller.
OPTIMISTIC_CONSTRAINED = (
    "the bands read for the robot's best law (Pmaxmax) for the task and the constraints "
    "together: the bracket is the best case over the bands of a policy meeting the "
    "constraints under the law it is played with; the controller reaches it, and meets "
    "the constraints, only when the events follow that law, and guarantees nothing under "
    "a law of nature's choosing (bands 'worst' gives the guarantee)")

@dataclass(frozen=True, slots=True, eq=False)
class OptimisticPart(ConstrainedPart):
    """The constrained part of an answer with the bands read for their best law: its
    policy is on the merged model of the cooperative MDP (:func:`cooperative_mdp`)."""

    reading: str = "best"


def cooperative_mdp(imdp: IntervalMDP, vr: VertexRows | None = None) -> MDP:
    """The MDP whose choices are the pairs (robot choice ``c`` of ``imdp``, vertex row
    ``v`` of ``c``), in the order of ``vertex_rows(imdp)``: choice ``vr.groups[c] + v``
    has ``c``'s action and vertex row ``v``'s distribution (module docstring)."""
    vr = vertex_rows(imdp) if vr is None else vr
    per = np.diff(vr.groups)
    fields = imdp.choice_fields()
    fields["row_groups"] = np.asarray(vr.groups[imdp.row_groups], dtype=np.int64)
    fields["choice_actions"] = np.repeat(np.asarray(imdp.choice_actions), per)
    return MDP(matrix=vr.matrix, **fields)


def independent_weights(imdp: IntervalMDP, vr: VertexRows, weight: np.ndarray
                        ) -> np.ndarray:
    """``weight`` (per cooperative choice, :func:`cooperative_mdp`: a randomised policy's
    probabilities) with each choice's mixture of vertex rows replaced by the law of
    independent hazards with the same chance of each band event's upper hazard: weight
    ``total * prod_i t_i^{v_i} (1 - t_i)^{1 - v_i}`` on vertex ``v``.  Unchanged on a
    choice with at most one band event (any mixture of its two rows is a hazard of the
    band) and on a mixture that is already of that form (within rounding)."""
    out = np.array(weight, dtype=np.float64, copy=True)
    k = np.diff(imdp.band_groups).astype(np.int64)
    for c in np.flatnonzero(k >= 2).tolist():
        lo, hi = int(vr.groups[c]), int(vr.groups[c + 1])
        w = out[lo:hi]
        total = float(w.sum())
        if total <= 0.0:
            continue
        bits = (np.arange(hi - lo)[:, None] >> np.arange(int(k[c]))[None, :]) & 1
        t = (w / total) @ bits  # each event's chance of its upper hazard
        out[lo:hi] = total * np.prod(np.where(bits == 1, t[None, :], 1.0 - t[None, :]),
                                     axis=1)
    return out


def solve_optimistic_constrained(posed: Posed, built: Built, *,
                                 costs: Mapping[str, float] | None = None,
                                 seed: int | None = 0) -> Result:
    """The optimistic constrained optimum of the module docstring for a posed problem
    with constraints (or ``then``) and a band read for its best law, on its built joint
    interval MDP."""
    t0 = time.perf_counter()
    imdp, joint, sta = built.mdp, built.joint, built.sta
    assert isinstance(imdp, IntervalMDP) and joint is not None
    vr = vertex_rows(imdp)
    coop = cooperative_mdp(imdp, vr)
    r = solve_merged(posed, coop, joint, sta, t0, costs=costs, seed=seed,
                     build=built.timings, part=OptimisticPart)
    bands = {e: str(c.distribution) for e, c in sorted(sta.clocks.items())
             if c.distribution.is_ambiguous}
    part = r.part
    assert isinstance(part, ConstrainedPart)
    if r.status != Status.OPTIMAL or part.prob is None or part.merged is None:
        return replace(r, bands=bands, part=replace(part, message=(
            f"{r.message}; with the bands read for their best law (no law of the bands "
            "lets a policy meet the constraints)")))
    merged = part.merged
    origin = np.asarray(merged.choice_origin)
    real = origin >= 0  # a keep choice (a safety part kept) has no vertex row
    weight = np.zeros(coop.n_choices)
    weight[origin[real]] = np.asarray(part.prob)[real]
    snapped = independent_weights(imdp, vr, weight)
    moved = float(np.max(np.abs(snapped - weight), initial=0.0))
    law = at_law(imdp, vr, snapped)
    law_merged = merge(law, joint, negated=posed.minimise)
    prob, stay, unmapped = _mapped(merged, law_merged, imdp, vr, part.prob, part.stay)
    r = replace(r, mdp=law, part=replace(part, merged=law_merged, prob=prob, stay=stay))
    return _judged(posed, r, prob, moved, bands, seed, unmapped,
                   dict(posed.model.costs if costs is None else costs))


def at_law(imdp: IntervalMDP, vr: VertexRows, weight: np.ndarray) -> MDP:
    """The product at nature's chosen law: the MDP with ``imdp``'s choices whose row of
    choice ``c`` is the mixture of its vertex rows by ``weight`` (per cooperative choice,
    :func:`cooperative_mdp`), or, for a choice ``weight`` gives nothing, its row at the
    middle law of the bands (a law within them)."""
    from mitld_lp.product.imdp import middle_rows

    per = np.diff(vr.groups)
    robot = np.repeat(np.arange(imdp.n_choices), per)
    totals = np.bincount(robot, weights=weight, minlength=imdp.n_choices)
    share = np.divide(weight, totals[robot], out=np.zeros_like(weight),
                      where=totals[robot] > 0)
    pick = sp.csr_array((share, (robot, np.arange(robot.size))),
                        shape=(imdp.n_choices, robot.size))
    idle = sp.diags_array((totals <= 0).astype(np.float64))
    rows = sp.csr_array(pick @ vr.matrix + idle @ middle_rows(imdp))
    rows.eliminate_zeros()
    rows.sort_indices()
    return point_mdp(imdp, rows)


def _mapped(coop: Merged, law: Merged, imdp: IntervalMDP, vr: VertexRows,
            prob: np.ndarray, stay: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The randomised policy ``prob`` / ``stay`` of the cooperative merged model moved
    to the merged model at nature's law: a robot choice's probability is the sum of its
    pairs'; a keep choice, a stay and an absorbing state's loop go to the same product
    state's.  Also what could not be moved (a keep or a stay where the law's model has
    no end component to play it in)."""
    robot = np.repeat(np.arange(imdp.n_choices), np.diff(vr.groups))
    law_choice = np.full(imdp.n_choices, -1, dtype=np.int64)
    lo = np.asarray(law.choice_origin)
    law_choice[lo[lo >= 0]] = np.flatnonzero(lo >= 0)
    ccs, lcs = coop.mdp.choice_state(), law.mdp.choice_state()

    def state_of(ms: int) -> int:  # the law's merged state of coop's merged state ms
        p = int(coop.origin[ms])
        if p >= 0:
            return int(law.state_map[p])
        same = np.flatnonzero(law.absorbing & (law.truncated == coop.truncated[ms])
                              & (law.verdicts == coop.verdicts[ms]).all(axis=1))
        return int(same[0]) if same.size else -1

    out_prob = np.zeros(law.mdp.n_choices)
    out_stay = np.zeros(law.mdp.n_states)
    problems: list[str] = []
    for mc in np.flatnonzero(prob > 0).tolist():
        o = int(coop.choice_origin[mc])
        if o >= 0:
            to = int(law_choice[robot[o]])
        else:  # a keep choice or an absorbing state's loop: the same state's
            ls = state_of(int(ccs[mc]))
            kind = law.keep if coop.keep[mc] else (np.asarray(law.choice_origin) < 0)
            there = np.flatnonzero((lcs == ls) & kind) if ls >= 0 else np.zeros(0, int)
            to = int(there[0]) if there.size else -1
        if to < 0:
            problems.append(f"choice {mc} ({'keep' if coop.keep[mc] else 'move'})")
            continue
        out_prob[to] += prob[mc]
    for ms in np.flatnonzero(stay > 0).tolist():
        ls = state_of(ms)
        if ls < 0 or not law.stay_ok[ls]:
            problems.append(f"a stay at state {ms}")
            continue
        out_stay[ls] = stay[ms]
    return out_prob, out_stay, problems


def _judged(posed: Posed, r: Result, prob: np.ndarray, moved: float, bands: dict[str, str],
            seed: int | None, unmapped: list[str], cost_map: dict[str, float]) -> Result:
    """``r`` (the LP's answer on the cooperative MDP) with its policy ``prob`` (a law of
    the bands, :func:`independent_weights`) evaluated in exact arithmetic: the task from
    below and each constraint on the side that matters.  The LP's upper bound stands
    (every law of the bands is a mixture of vertex rows).  A constraint this policy
    breaks leaves ``lower`` unclaimed (NaN) and the status ``failed``."""
    from mitld_lp.controllers.kinds import ConstrainedController
    from mitld_lp.routes.constrained import ConstraintValue, cost_vector, rows_for
    from mitld_lp.solvers.constrained import certified_value
    from mitld_lp.solvers.constrained_model import Quantity
    from mitld_lp.solvers.rounding import model_eta, one_minus

    part = r.part
    assert isinstance(part, ConstrainedPart) and part.stay is not None
    merged, stay, cons = part.merged, part.stay, posed.problem.constraints
    eta = model_eta(r.sta)
    costs = cost_vector(r.mdp, cost_map)
    task = certified_value(merged, prob, stay, Quantity("prob", 0, 0.0),
                           "lower bound: the policy's task probability", eta=eta)
    values = []
    for c, row in zip(cons, rows_for(cons, "lower"), strict=True):
        b = certified_value(merged, prob, stay, row.quantity, f"{c}", costs=costs, eta=eta)
        side = b.upper if c.sense == "<=" else b.lower
        holds = b.check.passed and (side <= c.bound if c.sense == "<=" else side >= c.bound)
        values.append(ConstraintValue(c, float(b.value), bool(holds),
                                      bounds=(b.lower, b.upper)))
    steps = certified_value(merged, prob, stay, Quantity("steps"), "expected steps")
    secondary = part.secondary
    if r.then is not None:
        secondary = (steps if r.then == "min-steps" else certified_value(
            merged, prob, stay, Quantity("cost"), "expected cost", costs=costs)).value
    ok = task.check.passed and all(v.holds for v in values) and not unmapped
    raw_upper = r.complement[1] if r.complement is not None else r.upper
    raw_lower = task.lower if ok else float("nan")
    if posed.minimise:
        complement = (raw_lower, raw_upper)
        lower, upper = (one_minus(raw_lower, raw_upper) if ok else
                        (one_minus(0.0, raw_upper)[0], float("nan")))
    else:
        complement, lower, upper = None, raw_lower, raw_upper
    width = dict(r.width)
    total = raw_upper - raw_lower
    width["solver"] = max(total - sum(v for k, v in width.items()
                                      if k not in ("total", "solver")), 0.0)
    width["total"] = total
    own = ("lower bound: the policy's task probability", "precision")
    checks = [c for c in r.checks if c.name not in own and not c.name.startswith("constraint ")]
    checks += [task.check,
               *(Check(f"constraint {v.constraint}", v.holds,
                       f"{v.value!r} in [{v.bounds[0]!r}, {v.bounds[1]!r}]") for v in values),
               Check("the optimistic law is a law of the bands", not unmapped,
                     "nature's mixtures of corners read as independent hazards (moved by "
                     f"{moved:.3g}); the policy played at that law" + (
                         "" if not unmapped else ": not playable there: "
                         + ", ".join(unmapped[:3]))),
               precision_check(raw_lower, raw_upper, width["solver"],
                               width.get("truncation", 0.0), r.precision)]
    old = r.controller
    controller = ConstrainedController(old.game, old.sta, part.joint, merged, r.mdp, prob,
                                       stay, seed=seed)
    return replace(r, lower=lower, upper=upper, complement=complement, checks=tuple(checks),
                   certified=all(c.passed for c in checks),
                   status=r.status if ok else Status.FAILED, bands=bands, width=width,
                   controller=controller,
                   part=replace(part, prob=prob, constraints=tuple(values),
                                steps=steps.value, secondary=secondary,
                                message=f"{part.message}; {OPTIMISTIC_CONSTRAINED}"
                                + ("" if ok else "; the policy at nature's chosen law "
                                   "breaks a constraint or cannot be played there: no "
                                   "lower bound claimed")))
