"""Constraints when some law is known only within a band: a sound bracket on the robust
constrained optimum (docs/robust.md, "Constraints").

The robust constrained optimum is the best probability of the task the robot can
guarantee whatever law of the bands the events follow, over the policies whose every
constraint holds whatever law of the bands they follow::

    V* = max { min_nu P_nu^pi(task) : pi such that for all nu, every constraint holds }

It is bracketed on the interval MDP of the joint product:

* ``upper``: the smaller of the constrained optimum (upper model, truncation won) at one
  law of the bands, the *middle law* (every hazard at the middle of its interval, at
  every step) -- a policy that meets the constraints under every law meets them under
  that one, and its worst case is at most its value there -- and the robust optimum of
  the task without constraints and ``then`` (:mod:`mitld_lp.routes.robust`, certified),
  which no constrained policy beats.
* ``lower``: a policy's task value against every law of the bands, from below, for a
  policy whose every constraint's worst case is within its bound (from above for
  ``P(.) <= x`` and ``E(.) <= x``, from below for ``P(.) >= x``): a probability's by
  robust interval iteration (:func:`worst_case`), an expected total's by nature's
  maximum (:func:`mitld_lp.solvers.robust_merged.worst_total`), nature choosing the
  corner of the hazard box for each of the policy's choices at every step.  Such a
  policy is one of those ``V*`` ranges over, so ``lower <= V*``.  The policy is found
  in this order: the policy optimal at the middle law; that LP solved again with each
  bound the bands break tightened by what they added (:data:`ROUNDS` rounds, a bound
  missed again tightened by at least twice its last step, an infeasible LP's margins
  halved back); the robot's robust policy of each probability constraint alone
  (:func:`mitld_lp.solvers.robust_merged.robust_for`).  If none meets every bound
  against every law, the status is ``failed``, ``lower`` is NaN, no constraint is said
  to hold, and the answer says the feasibility is unknown (with each probability
  constraint alone's robust optimum, :func:`alone_bounds`).  A problem infeasible at the
  middle law is infeasible at every law; so is one with a probability constraint whose
  formula alone has its robust optimum beyond the bound (the status ``infeasible``).

``then`` (``min-steps``/``min-cost``) with a band: what is optimised is the middle law's
lexicographic LP (the fastest or cheapest of the policies optimal there, within the
constraints tightened as above); what is evaluated is that policy's worst case over the
bands: its task value (``lower``), and its expected steps (and cost) with nature
maximising them, a certified interval (``steps``, ``secondary``, the checks).  The
fastest policy at the worst law is not searched for.

The width ``upper - lower`` is what the bands leave open beyond the truncation; the
answer says it.

With the bands read for their best law (``Settings.bands = "best"``) the route solves
the optimistic constrained optimum instead (:mod:`mitld_lp.routes.optimistic_constrained`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.joint import ACCEPTED
from mitld_lp.checks import Check
from mitld_lp.controllers.kinds import ConstrainedController
from mitld_lp.problem import Posed, pose_on
from mitld_lp.product import robust_product
from mitld_lp.product.imdp import IntervalMDP, VertexRows, middle_rows, point_mdp, vertex_rows
from mitld_lp.result import Result
from mitld_lp.routes.constrained import (
    ConstrainedPart,
    ConstraintValue,
    lp_refusals,
    quantity_of,
    solve_merged,
)
from mitld_lp.routes.route import Route
from mitld_lp.routes.stages import Built, build_joint
from mitld_lp.solvers.result import Status

if TYPE_CHECKING:  # the LP's and the robust game's modules load when solving
    from mitld_lp.solvers.constrained_model import Merged, Quantity
    from mitld_lp.solvers.robust_graph import RobustGame

__all__ = ["RobustConstrainedRoute", "solve_robust_constrained", "worst_case",
           "tighten_margins", "alone_bounds", "ROUNDS"]

log = logging.getLogger(__name__)

ROUNDS = 8
"""How many times the middle-law LP is solved again with tightened bounds."""


def worst_case(merged: Merged, vr: VertexRows, prob: np.ndarray, stay: np.ndarray,
               q: Quantity, *, nature_maximises: bool, tol: float,
               eta: float | None = None) -> tuple[float, float]:
    """Bounds ``(lo, hi)`` at the initial state on the probability of ``q`` under
    the randomised policy ``(prob, stay)`` of ``merged`` when nature picks, for each of the
    policy's choices and each step, a corner of the choice's hazard box (vertex rows
    ``vr`` of the product, mapped to the merged states) to minimise it (or to maximise
    it, ``nature_maximises``).  Nature choosing per choice has at least the power of one
    hazard per step, so the bounds hold for every law of the bands.  The side nature
    pushes (``hi`` when it maximises, else ``lo``) holds in exact arithmetic for the
    model's probabilities within ``eta`` of the stored ones (:func:`_checked`); the
    other is robust interval iteration's, to its tolerance.

    The robust game: each live merged state has one choice, to a node per policy choice
    (weight ``prob[c]``) and to WIN or LOSE for its stay (worth the stay's verdict); a
    node's rows are its choice's vertex rows (nature's rows when it minimises; the
    player's choices, one row each, when it maximises)."""
    from mitld_lp.solvers.robust import robust_interval_iteration, sweep_budget
    from mitld_lp.solvers.robust_graph import RobustGame

    mdp = merged.mdp
    m = mdp.n_states
    rg = np.asarray(mdp.row_groups)
    cs = mdp.choice_state()
    live = ~merged.absorbing
    used = np.flatnonzero((prob > 0) & live[cs])
    node = np.full(mdp.n_choices, -1, dtype=np.int64)
    node[used] = m + np.arange(used.size)
    win, lose = m + used.size, m + used.size + 1
    n = lose + 1
    if q.kind != "prob":
        raise ValueError("worst_case: probabilities only")
    if eta is None:
        from mitld_lp.solvers.rounding import ETA

        eta = ETA
    sat = merged.verdicts[:, q.component] == ACCEPTED
    target = np.zeros(n, dtype=bool)
    target[:m] = merged.absorbing & sat
    target[:m][merged.truncated] = q.truncated == 1.0
    target[win] = True
    # rows: (player choices of each state) -> list of (vertex rows)
    r_rows: list[np.ndarray] = []
    r_cols: list[np.ndarray] = []
    r_vals: list[np.ndarray] = []
    rows_per_choice: list[int] = []
    choices_per_state = np.zeros(n, dtype=np.int64)
    row_count = 0

    def add_row(cols: np.ndarray, vals: np.ndarray) -> None:
        nonlocal row_count
        r_rows.append(np.full(cols.size, row_count, dtype=np.int64))
        r_cols.append(cols.astype(np.int64))
        r_vals.append(vals.astype(np.float64))
        row_count += 1

    # merged states, in order: one choice each
    for s in range(m):
        choices_per_state[s] = 1
        rows_per_choice.append(1)
        if not live[s]:
            add_row(np.array([s]), np.array([1.0]))
            continue
        cols = [node[c] for c in range(rg[s], rg[s + 1]) if node[c] >= 0]
        vals = [prob[c] for c in range(rg[s], rg[s + 1]) if node[c] >= 0]
        if stay[s] > 0:
            cols.append(win if sat[s] else lose)
            vals.append(stay[s])
        add_row(np.array(cols, dtype=np.int64), np.array(vals))
    vm = vr.matrix
    for c in used.tolist():
        origin = int(merged.choice_origin[c])
        if origin < 0:  # a keep choice: into its verdict state
            row = mdp.matrix[[c]].tocoo()
            vertex = [(row.col, row.data)]
        else:
            lo, hi = int(vr.groups[origin]), int(vr.groups[origin + 1])
            vertex = []
            for r in range(lo, hi):
                a, b = vm.indptr[r], vm.indptr[r + 1]
                mapped = merged.state_map[vm.indices[a:b]]
                if (mapped < 0).any():
                    raise AssertionError("a vertex row leaves the merged model")
                vertex.append((mapped, vm.data[a:b]))
        if nature_maximises:  # the player picks: one choice per vertex row
            choices_per_state[node[c]] = len(vertex)
            for cols_, vals_ in vertex:
                rows_per_choice.append(1)
                add_row(cols_, vals_)
        else:
            choices_per_state[node[c]] = 1
            rows_per_choice.append(len(vertex))
            for cols_, vals_ in vertex:
                add_row(cols_, vals_)
    for sink in (win, lose):
        choices_per_state[sink] = 1
        rows_per_choice.append(1)
        add_row(np.array([sink]), np.array([1.0]))
    matrix = sp.csr_array((np.concatenate(r_vals), (np.concatenate(r_rows),
                                                    np.concatenate(r_cols))),
                          shape=(row_count, n))
    matrix.sum_duplicates()
    vertex_groups = np.zeros(len(rows_per_choice) + 1, dtype=np.int64)
    np.cumsum(rows_per_choice, out=vertex_groups[1:])
    row_groups = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(choices_per_state, out=row_groups[1:])
    game = RobustGame(matrix, vertex_groups, row_groups)
    it = robust_interval_iteration(game, target, tol=tol, max_sweeps=sweep_budget(game))
    if it.status is not Status.OPTIMAL:  # the bracket is sound, only wider than tol
        log.warning("worst case of %s: %s; its bounds are the iteration's so far",
                    q.kind, it.message)
    return _checked(game, target, it, nature_maximises, eta, int(mdp.initial),
                    int(np.max(np.diff(rg), initial=1)) + 1)


def _checked(game: RobustGame, target: np.ndarray, it: Any, nature_maximises: bool,
             eta: float, s0: int, width: int) -> tuple[float, float]:
    """The side of the worst case that matters bounded in exact arithmetic
    (:mod:`mitld_lp.solvers.certify`): nature, one player, is an MDP's maximiser (an
    upper bound on its maximum) or minimiser (a lower bound on its minimum); the other
    side is the iteration's.  A policy's row is its floats normalised by their exact
    sum, within ``gamma_width`` of the floats: added to ``eta``."""
    from mitld_lp.solvers.certify import RowModel, certify
    from mitld_lp.solvers.rounding import UNIT

    model = RowModel(game.matrix, game.vertex_groups[game.row_groups], s0)
    values = np.asarray(it.lower if not nature_maximises else it.upper, dtype=np.float64)
    scores = game.matrix @ values
    groups = model.row_groups
    best = (np.maximum if nature_maximises else np.minimum).reduceat(scores, groups[:-1])
    rows = np.arange(scores.shape[0])
    hit = scores == np.repeat(best, np.diff(groups))
    strategy = np.minimum.reduceat(np.where(hit, rows, rows.shape[0]), groups[:-1])
    strategy = np.where(target, -1, strategy)
    eta = eta + 2.0 * width * UNIT / (1.0 - width * UNIT)
    if nature_maximises:
        cert = certify(model, target, strategy, sense="max", sides=("upper",),
                       zero=np.asarray(it.prob0, dtype=bool), fallback_upper=it.upper,
                       eta=eta)
        return float(it.lower[s0]), cert.upper
    cert = certify(model, target, strategy, sense="min", sides=("lower",),
                   zero=np.asarray(it.prob0, dtype=bool),
                   one=np.asarray(it.prob1, dtype=bool), fallback_lower=it.lower, eta=eta)
    return cert.lower, float(it.upper[s0])


def solve_robust_constrained(posed: Posed, built: Built, *,
                             costs: Mapping[str, float] | None = None,
                             seed: int | None = 0) -> Result:
    """The sound bracket of the module docstring for a posed problem with constraints (or
    ``then``) and a band, on its built joint interval MDP
    (:func:`mitld_lp.synthesis.solve`)."""
    from mitld_lp.routes.constrained import cost_vector
    from mitld_lp.solvers.constrained import OPTIMAL
    from mitld_lp.solvers.rounding import model_eta, one_minus

    s = posed.settings
    t0 = time.perf_counter()
    imdp, joint, sta = built.mdp, built.joint, built.sta
    assert isinstance(imdp, IntervalMDP) and joint is not None
    middle = point_mdp(imdp, middle_rows(imdp))
    nominal = solve_merged(posed, middle, joint, sta, t0, costs=costs, seed=seed,
                           build=built.timings)
    bands = {e: str(c.distribution) for e, c in sorted(sta.clocks.items())
             if c.distribution.is_ambiguous}
    assert isinstance(nominal.part, ConstrainedPart)  # solve_merged's answer
    if nominal.status != OPTIMAL:  # infeasible at one law of the bands: at every law too
        return replace(nominal, bands=bands, part=replace(nominal.part, message=(
            f"{nominal.message}; at the middle law of the bands (a law within them: no "
            "policy meets the constraints under every law either)")))
    t1 = time.perf_counter()
    minimise, cons, then = posed.minimise, posed.problem.constraints, posed.problem.then
    # the nominal answer is read in the task's terms; the robust evaluation works on the
    # maximised automaton (the complement's for a minimised task)
    raw_upper = 1.0 - nominal.lower if minimise else nominal.upper
    robust_upper = _robust_upper(posed)
    upper_by = "the optimum at the middle law"
    if robust_upper < raw_upper:
        raw_upper, upper_by = robust_upper, "the robust optimum without constraints"
    assert nominal.part.merged is not None
    judge = _Judge(nominal.part.merged, vertex_rows(imdp), cons, s.tol, model_eta(sta),
                   cost_vector(middle, dict(posed.model.costs if costs is None else costs)))
    best, rounds, margins = _tighten(posed, middle, joint, sta, t0, costs, seed, built,
                                     nominal, judge)
    fallback = ""
    if best is None:  # the robot's robust policy for each probability constraint alone
        best, fallback = _fallback(nominal, judge, seed)
    robust_ok = best is not None
    none, alone = (None, "") if robust_ok else alone_bounds(posed)
    if none is not None:  # a constraint alone is beyond its bound under the bands
        return replace(nominal, lower=float("nan"), upper=float("nan"),
                       value=float("nan"), status=Status.INFEASIBLE, controller=None,
                       certified=False, bands=bands, part=replace(
                           nominal.part, message=f"infeasible under the bands: {none}",
                           constraints=tuple(replace(v, holds=False)
                                             for v in judge.values(nominal))))
    chosen, values, lower = best if best is not None else (nominal, judge.values(nominal),
                                                           float("nan"))
    extra = _then_checks(chosen, judge, then)
    width = raw_upper - lower
    # the middle law's own precision and constraint checks are not this answer's
    kept = [c for c in chosen.checks
            if c.name != "precision" and not c.name.startswith("constraint ")]
    checks = (*kept, *extra[0],
              Check("constraints hold against every law of the bands", robust_ok,
                    "; ".join(f"{v.constraint}: worst case {v.certified!r}" for v in values)
                    or "no constraint"),
              Check("robust lower <= upper",
                    bool(robust_ok and lower <= raw_upper + s.certify_tol),
                    f"{lower!r} <= {raw_upper!r}"))
    eps = nominal.sta.epsilon_achieved
    how = fallback or "a policy optimal at the middle law of the bands" + (
        f" (its bounds tightened in {rounds} rounds by "
        + ", ".join(f"{m:.3g}" for m in margins) + ")" if rounds else "")
    message = (f"robust bracket: {how} against their worst law (lower) and {upper_by} "
               f"(upper); width {width:.3g}"
               + (f", wider than the truncation's {eps:.3g}: the bands leave it open"
                  if width > eps + s.certify_tol else "") + extra[1]
               if robust_ok else
               "no policy found that meets every constraint under every law of the bands "
               "(the middle law's optimum, tightened" + (
                   ", and the robust policy of each probability constraint alone"
                   if any(c.kind == "prob" for c in cons) else "")
               + ", break one): feasibility unknown, no certified lower bound" + (
                   f" (each bound is within what the constraint alone reaches: {alone})"
                   if alone else ""))
    complement = None
    if minimise:
        complement = (lower, raw_upper)
        lower, upper = (one_minus(lower, raw_upper) if robust_ok else
                        (one_minus(0.0, raw_upper)[0], float("nan")))
    else:
        upper = raw_upper
    timings = {**nominal.timings, "robust": time.perf_counter() - t1}
    assert isinstance(chosen.part, ConstrainedPart)
    return replace(chosen, lower=lower, upper=upper, value=nominal.value,
                   status=OPTIMAL if robust_ok else Status.FAILED,
                   part=replace(chosen.part, constraints=tuple(values), message=message,
                                options=judge.opts, **extra[2]),
                   certified=all(c.passed for c in checks), checks=checks, bands=bands,
                   timings=timings, complement=complement,
                   width={"total": width, "bands": width})


def _robust_upper(posed: Posed) -> float:
    """The robust optimum of the task without constraints and ``then``, from above, in
    the maximised automaton's terms (the complement's for a minimised task): no policy
    meeting the constraints guarantees more (``inf`` when it is not certified)."""
    from mitld_lp.routes.robust import solve_robust
    from mitld_lp.routes.stages import build_interval

    alone = replace(posed, problem=replace(posed.problem, constraints=(), then=None))
    r = solve_robust(alone, build_interval(alone, False))
    if not r.certified:
        return float("inf")
    if posed.minimise:
        return float(r.complement[1]) if r.complement else 1.0 - float(r.lower)
    return float(r.upper)


def alone_bounds(posed: Posed) -> tuple[str | None, str]:
    """Each probability constraint's formula alone, seeing every event: its robust
    optimum over the bands (:mod:`mitld_lp.routes.robust`; the least worst case of a
    ``P(.) <= x``, the greatest of a ``P(.) >= x``), which no controller -- fully
    observed or acting on sensor reports -- betters under every law.  Returns why no
    policy meets the constraints under every law (a constraint whose bracket lies beyond
    its bound; None when none does) and what the brackets say (empty when none was
    solved).  A bracket the robust route does not give (a budget, a refusal) is left out
    and logged."""
    import dataclasses
    from types import MappingProxyType

    from mitld_lp.problem import ProblemError
    from mitld_lp.routes.robust import RobustRoute
    from mitld_lp.util.memory import ProductTooLarge

    settings = replace(posed.settings, progress=False, bands="worst")
    said: list[str] = []
    for c in posed.problem.constraints:
        if c.kind != "prob":
            continue
        model = dataclasses.replace(
            posed.model, spec=c.formula, spec_text=c.text, constraints=(),
            sensors=MappingProxyType({}), objective="min" if c.sense == "<=" else "max")
        try:
            alone = pose_on([RobustRoute(points=True)], model, settings=settings)
            r = alone.route.solve(alone, alone.route.build(alone, False))
        except (ProblemError, ProductTooLarge) as exc:
            log.info("constraint %s alone, seeing every event: not solved (%s)", c, exc)
            continue
        if not r.certified:
            log.info("constraint %s alone, seeing every event: not certified", c)
            continue
        best = r.lower if c.sense == "<=" else r.upper  # what no policy betters
        if (best > c.bound) if c.sense == "<=" else (best < c.bound):
            return (f"{c} alone, seeing every event, has its robust optimum over the bands "
                    f"in [{r.lower!r}, {r.upper!r}]: no policy meets it under every law"), ""
        said.append(f"{c} alone, seeing every event: robust optimum in "
                    f"[{r.lower!r}, {r.upper!r}]")
    return None, "; ".join(said)


class _Judge:
    """A policy of the merged model judged against every law of the bands: each
    constraint's worst case (:func:`worst_case` for a probability, nature's maximum of the
    expected total for steps and cost, :func:`mitld_lp.solvers.robust_merged.worst_total`)
    and the task's worst case from below."""

    def __init__(self, merged: Merged, vr: VertexRows, cons: tuple[Any, ...], tol: float,
                 eta: float, costs: np.ndarray) -> None:
        from mitld_lp.solvers.robust_merged import options

        self.merged, self.vr, self.cons, self.tol, self.eta, self.costs = \
            merged, vr, cons, tol, eta, costs
        self.opts = options(merged, vr)

    def values(self, result: Result) -> list[ConstraintValue]:
        """Each constraint's worst case under ``result``'s policy, bounded in exact
        arithmetic on the side that matters, and whether that meets the bound exactly."""
        from mitld_lp.solvers.constrained_model import Quantity
        from mitld_lp.solvers.robust_merged import worst_total

        assert result.prob is not None and result.stay is not None
        out, k = [], 0
        for c in self.cons:
            k += c.kind == "prob"
            if c.kind == "prob":
                lo, hi = worst_case(self.merged, self.vr, result.prob, result.stay,
                                    quantity_of(c, k, "lower"),
                                    nature_maximises=c.sense == "<=", tol=self.tol,
                                    eta=self.eta)
                worst, ok = (hi if c.sense == "<=" else lo), True
            else:
                w = worst_total(self.merged, self.opts, result.prob, result.stay,
                                Quantity(c.kind), costs=self.costs, eta=self.eta)
                lo, hi, worst, ok = w.lower, w.upper, w.upper, w.check.passed
            holds = ok and (worst <= c.bound if c.sense == "<=" else worst >= c.bound)
            out.append(ConstraintValue(c, worst, bool(holds), bounds=(lo, hi)))
        return out

    def task(self, prob: np.ndarray, stay: np.ndarray) -> float:
        """The task's worst case under the policy, from below."""
        from mitld_lp.solvers.constrained_model import Quantity

        return worst_case(self.merged, self.vr, prob, stay, Quantity("prob", 0, 0.0),
                          nature_maximises=False, tol=self.tol, eta=self.eta)[0]


Candidate = tuple[Result, list[ConstraintValue], float]


def _tighten(posed: Posed, middle: Any, joint: Any, sta: Any, t0: float,
             costs: Mapping[str, float] | None, seed: int | None, built: Built,
             nominal: Result, judge: _Judge) -> tuple[Candidate | None, int, list[float]]:
    """The middle law's LP solved again with each bound the bands break tightened by
    what they added, and a little more (:data:`ROUNDS` rounds); a tightened LP that is
    infeasible is solved again with the margins halved back towards the last feasible
    ones; a bound missed again is tightened by at least twice its last step.  The
    policy found that meets every bound against every law, the rounds and the
    margins."""
    from mitld_lp.solvers.constrained import OPTIMAL

    cons = posed.problem.constraints
    chosen, values = nominal, judge.values(nominal)
    margins = [0.0] * len(cons)
    steps = [0.0] * len(cons)
    rounds = 0
    while not all(v.holds for v in values):
        if rounds >= ROUNDS:
            return None, rounds, margins
        rounds += 1
        good = list(margins)  # the last margins whose LP was feasible
        margins = tighten_margins(values, margins, steps)
        again = None
        for _ in range(4):
            tight = tuple(replace(c, bound=c.bound - margins[i] if c.sense == "<=" else
                                  c.bound + margins[i]) for i, c in enumerate(cons))
            again = solve_merged(replace(posed, problem=replace(posed.problem,
                                                                constraints=tight)),
                                 middle, joint, sta, t0, costs=costs, seed=seed,
                                 build=built.timings)
            if again.status == OPTIMAL:
                break
            margins = [0.5 * (a + b) for a, b in zip(good, margins, strict=True)]
            again = None
        if again is None:
            return None, rounds, margins
        chosen, values = again, judge.values(again)
    assert chosen.prob is not None and chosen.stay is not None
    return (chosen, values, judge.task(chosen.prob, chosen.stay)), rounds, margins


def tighten_margins(values: Any, margins: list[float], steps: list[float]) -> list[float]:
    """The margins by which each constraint's bound is moved in, grown for each bound a
    candidate's worst case ``values`` (:class:`ConstraintValue`, in the constraints'
    order) misses: by what the bands added and a little more, and at least twice the last
    step (``steps``, updated) when a bound is missed again."""
    out = list(margins)
    for i, v in enumerate(values):
        if not v.holds:
            excess = abs(v.value - v.constraint.bound) if v.value == v.value else 0.0
            steps[i] = max(1.5 * excess + 1e-9 * (1.0 + abs(v.constraint.bound)),
                           2.0 * steps[i])
            out[i] += steps[i]
    return out


def _fallback(nominal: Result, judge: _Judge, seed: int | None
              ) -> tuple[Candidate | None, str]:
    """The robot's robust policy for each probability constraint alone (maximising the
    worst case of a ``>=`` one, minimising that of a ``<=`` one), judged against every
    constraint: the first that meets them all, with its task's worst case."""
    from mitld_lp.solvers.robust_merged import robust_for

    k = 0
    for c in judge.cons:
        k += c.kind == "prob"
        if c.kind != "prob":
            continue
        prob, stay = robust_for(judge.merged, judge.opts, quantity_of(c, k, "lower"),
                                maximise=c.sense == ">=", tol=judge.tol)
        assert isinstance(nominal.part, ConstrainedPart)
        old = nominal.controller  # the middle law's: the candidate gets its own
        controller = ConstrainedController(old.game, old.sta, nominal.part.joint,
                                           judge.merged, nominal.mdp, prob, stay,
                                           seed=seed)
        candidate = replace(nominal, controller=controller,
                            part=replace(nominal.part, prob=prob, stay=stay))
        values = judge.values(candidate)
        if all(v.holds for v in values):
            return (candidate, values, judge.task(prob, stay)), (
                f"the robust policy of {c} alone (the middle law's optimum, tightened, "
                "breaks a bound under some law)")
    return None, ""


def _then_checks(chosen: Result, judge: _Judge, then: str | None
                 ) -> tuple[list[Check], str, dict[str, Any]]:
    """The chosen policy's expected steps (and, for ``then = "min-cost"``, cost) at the
    worst law of the bands, bracketed (nature maximising it): the answer's steps and
    secondary; with ``then`` the bracket's proof is a check of the answer."""
    from mitld_lp.solvers.constrained_model import Quantity
    from mitld_lp.solvers.robust_merged import worst_total

    assert chosen.prob is not None and chosen.stay is not None
    steps = worst_total(judge.merged, judge.opts, chosen.prob, chosen.stay,
                        Quantity("steps"), eta=judge.eta)
    fields: dict[str, Any] = {"steps": steps.upper}
    checks = [steps.check]
    text = (f"; E(steps) {steps.upper:.6g} at the worst law of the bands (in "
            f"[{steps.lower:.6g}, {steps.upper:.6g}])")
    if then == "min-cost":
        cost = worst_total(judge.merged, judge.opts, chosen.prob, chosen.stay,
                           Quantity("cost"), costs=judge.costs, eta=judge.eta)
        checks.append(cost.check)
        fields["secondary"] = cost.upper
        text += (f"; then min-cost: the middle law's cheapest, E(cost) {cost.upper:.6g} at "
                 f"the worst law (in [{cost.lower:.6g}, {cost.upper:.6g}])")
    elif then == "min-steps":
        fields["secondary"] = steps.upper
        text += "; then min-steps: the middle law's fastest"
    return (checks if then else []), text, fields


class RobustConstrainedRoute(Route):
    """Probability constraints with a law known only within a band: the sound bracket
    of the module docs on the joint interval MDP (with the bands read for their best
    law, :mod:`mitld_lp.routes.optimistic_constrained`).  ``every``: it claims problems
    without constraints too (:func:`mitld_lp.synthesis.synthesize_constrained`).  Its
    answer is a constrained one (``name``)."""

    name = "constrained"
    takes_constraints = True
    optimistic = True  # bands "best": mitld_lp.routes.optimistic_constrained

    def __init__(self, *, every: bool = False) -> None:
        self.every = every

    def claims(self, posed: Posed) -> bool:
        return (posed.problem.constrained or self.every) and posed.robust

    def refusal(self, posed: Posed) -> list[str]:
        return lp_refusals(posed)

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        from mitld_lp.routes.robust_tail import policy_side

        return build_joint(policy_side(posed), progress, make=robust_product)

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.routes.robust_tail import solve_tailed

        if posed.settings.bands == "best":
            from mitld_lp.routes.optimistic_constrained import solve_optimistic_constrained

            return solve_tailed(self, posed, built, lambda p, b: solve_optimistic_constrained(
                p, b, costs=costs, seed=seed))
        return solve_tailed(self, posed, built, lambda p, b: solve_robust_constrained(
            p, b, costs=costs, seed=seed))
