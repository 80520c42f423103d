"""The plain route (and the solve of any ordinary MDP with a reachability target): both
truncation models solved and certified.

    MDP --analyse--> quotients --interval iteration / occupancy LP--> two models
        --certificate--> ModelSolution x 2 --> Result

The product is built once (:mod:`mitld_lp.routes.stages`); its truncation sink counted
as losing gives the *lower* model, as winning the *upper* model.  Each model is solved
(occupancy LP or interval iteration) and certified (:mod:`mitld_lp.solvers.certify`):
the extracted deterministic policy is evaluated on its Markov chain, and the bounds the
answer reports are checked inequalities that hold in exact arithmetic on the model as
written: a lower bound on the policy's value (a sub-fixed point of its chain) and an
upper bound on the optimum (a pre-fixed point of the Bellman operator over every state
and choice), or for a minimum a lower bound on the optimum and an upper bound on the
policy's value.  The lower model's certificate gives ``lower``, the upper model's
``upper``; when nothing is truncated one model gives both.

A minimum (``sense="min"``: a co-safe task minimised on its own product,
:mod:`mitld_lp.routes.stages`) is solved as one, on quotients without end components
(:func:`mitld_lp.solvers.analysis.analyse`): the controller's policy is the upper
model's (truncation counted as the task happening: what the policy guarantees at most),
the bound no policy goes below the lower model's.

:func:`solve_models` is that solve on any MDP with a target (the sensed route's
information-state product uses it too); :func:`solve_plain` is the plain route.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from mitld_lp.checks import Check
from mitld_lp.controllers.kinds import Controller
from mitld_lp.mdp import MDP
from mitld_lp.problem import Posed, Settings, task_words
from mitld_lp.report import bracket_text
from mitld_lp.result import Part, Result, from_models
from mitld_lp.routes.route import Route
from mitld_lp.routes.stages import Built, build_task
from mitld_lp.util import heap
from mitld_lp.util.clock import Deadline
from mitld_lp.util.heap import release_free_memory

if TYPE_CHECKING:  # the solver stack is imported when a solve needs it (package docs)
    from mitld_lp.routes.acceptance import Acceptance
    from mitld_lp.solvers.quotient import Qualitative, Quotient
    from mitld_lp.solvers.result import IterationResult, Lifted, LPResult, Status

__all__ = ["PlainRoute", "PlainPart", "ModelSolution", "solve_models", "solve_plain",
           "TRIM_BEFORE_LP_FROM", "TRIM_FROM_TRANSITIONS"]

log = logging.getLogger(__name__)

#: The product size from which its builder's freed memory is handed back to the system
#: (:mod:`mitld_lp.util.heap`).  Below it the process's heap is tens of megabytes: its holes
#: do not matter, while the pages touched again cost a few percent of a short solve.
TRIM_FROM_TRANSITIONS = 1_000_000

#: The product size from which the free heap is handed back between the interval
#: iteration and the LPs too (:func:`solve_models`): the builder's threshold.  On
#: bus_scaled n128 d3 (7.1M transitions) it took the resident peak from 49.9 to 45.3-45.6
#: bytes a transition with no more solve CPU; on n64 d3 (1.77M), whose peak was the LP
#: stage's end (its greedy checks' SuperLU factorisations, kept for the certificates, then
#: the policy's flow), from 50.2-54.5 to 46.0-49.6 in alternated fresh processes, the peak now the
#: iteration's end, for 4-11 ms of the LP stage's CPU (the pages it faults in again), about
#: 3% of the solve (docs/results.md, lp-fast of 2026-12-02).  A trim before each greedy
#: check instead (46.2-46.7, two trims) was dearer, one before the flow alone (49.3-50.8)
#: saved too little.
TRIM_BEFORE_LP_FROM = TRIM_FROM_TRANSITIONS


@dataclass(frozen=True, slots=True, eq=False)
class ModelSolution:
    """The solution of one of the two models (lower: truncation loses; upper: it wins),
    optimised in ``sense`` (``"max"``, or ``"min"`` for a minimum solved as one)."""

    which: str
    status: Status
    value: float  # the method's optimum at the initial state
    policy: np.ndarray  # deterministic: a choice row per state, -1 where absorbing
    policy_values: np.ndarray  # exact value of ``policy`` in every state (read-only)
    bracket: tuple[float, float]  # interval iteration's sound bounds at the initial state
    lp: LPResult | None
    iteration: IterationResult
    prob0: np.ndarray  # (n_states,) bool: the states from which the target is unreachable
    checks: tuple[Check, ...]
    sense: str = "max"  # "max": the policy maximises; "min": it minimises
    # the certificate's bounds at the initial state (mitld_lp.solvers.certify): for
    # "max" a lower bound on the policy's value and an upper bound on the maximum, for
    # "min" a lower bound on the minimum and an upper bound on the policy's value; nan
    # for a side this model was not asked for
    bounds: tuple[float, float] = (float("nan"), float("nan"))
    # the values the graph decides, 0 or 1 (Storm's prob01, in ``sense``): every other
    # state's optimum is strictly between 0 and 1
    qualitative: Qualitative | None = None

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def quotient(self) -> NoReturn:
        """Gone: the reduction is released before the exact evaluations (its matrix was
        a second copy of most transitions); what the result needs of it is ``prob0``."""
        raise AttributeError("ModelSolution.quotient was removed: the reduction is freed "
                             "once the LPs are solved; use ModelSolution.prob0, or "
                             "mitld_lp.solvers.quotient.reduce(mdp, target) to rebuild it")


def _solve_lp(mdp: MDP, quotient: Quotient, it: IterationResult, s: Settings,
              deadline: Deadline, after: Quotient | None = None, primal: bool = True,
              ) -> LPResult | None:
    """The occupancy LP of one model (None for method ``"vi"``): it works on the model's
    :class:`Quotient`, made by the one analysis of the product both models share
    (:func:`mitld_lp.solvers.analysis.analyse`), with the bounds of ``it``, its interval
    iteration (both models are iterated in one pass, :func:`_iterate`).  ``after``: the
    next model's quotient, whose LP then reads this one's single-state levels where it
    shares the matrix (they are built once for both).  ``primal``: whether its primal
    point (the policy's flow) is made: the controller's model only (the report reads
    its primal objective; the bound's model's is NaN)."""
    if s.method != "lp":
        return None
    from mitld_lp.solvers.lp import solve_lp

    return solve_lp(mdp, np.asarray(quotient.target), quotient=quotient,
                    sense=quotient.sense, solver=s.solver, backend=s.backend,
                    tol=s.tol, precision=s.precision,
                    layout="blocks" if s.decompose is not False else "whole",
                    time_limit=deadline.left(),
                    bounds=(it.held_lower, it.held_upper),  # read on the quotient
                    everywhere=quotient.initial < 0, progress=s.progress,
                    flows=False,  # nothing reads a model's occupancy: not at the peak
                    primal=primal,
                    levels_after=after is not None and after.matrix is quotient.matrix
                    and after.order is quotient.order
                    and after.row_groups is quotient.row_groups)


def _certified(mdp: MDP, target: np.ndarray, decided: Qualitative,
               layers: tuple[np.ndarray, np.ndarray], mec_of: np.ndarray | None,
               it: IterationResult, lp: LPResult | None, which: str,
               s: Settings, eta: float, complement: bool,
               fallback: tuple[np.ndarray | Lifted | None, np.ndarray | Lifted | None],
               ) -> ModelSolution:
    """One model's answer and its certificate (module docs), on the product alone: the
    quotient's matrix is released by then.  Both bounds are checked on each model (the
    answer reads the lower model's lower one and the upper model's upper one), and that
    the policy is within the precision of the optimum in every state.  ``decided``: the
    graph's 0/1 sets in the model's sense (for a maximum ``zero`` is ``Prob0A``, the
    candidate upper bound's zeros; for a minimum ``Prob0E``, where the lower bound is 0,
    the end-component check guarding it, and ``one`` ``Prob1A``).  An LP that did not
    come back optimal (after its own retries) is replaced by the interval-iteration
    policy when it failed numerically (``INACCURATE``, ``MAX_ITERATIONS``); the
    certificate is the same whatever policy it reads.  ``fallback``: the iteration's
    bounds the certificate reads (:func:`_read_by_certificate`: on the quotient)."""
    from mitld_lp.solvers.certify import certify
    from mitld_lp.solvers.result import Status, read_only

    checks = [
        Check("iteration converged", it.status is Status.OPTIMAL, it.message),
    ]
    if _lp_policy(lp):
        policy, value, status = lp.policy, lp.value, lp.status
        checks.append(Check("LP solved", True, f"{lp.status.value}: {lp.message}"))
    else:  # the iteration's policy (made by _settled while the quotient lived)
        policy, value, status = it.policy, it.value_lower, it.status
        if lp is None:
            pass
        elif lp.status in (Status.INACCURATE, Status.MAX_ITERATIONS) and (
                it.status is Status.OPTIMAL):
            # A numerical failure after the LP's own retries: the answer is the converged
            # iteration's, certified below like method "vi"; the LP's word is kept.
            checks.append(Check("LP replaced by the iteration policy", True,
                                f"{lp.status.value}: {lp.message}"))
        else:  # a usage error (solver not installed), a time limit, or no fallback
            status = lp.status
            checks.append(Check("LP solved", False, f"{lp.status.value}: {lp.message}"))
    sense = str(decided.sense)
    minimum = sense == "min"
    cert = certify(mdp, target, policy, sense=sense, zero=decided.zero,
                   one=decided.one if minimum else None, mec_of=None if minimum else mec_of,
                   layers=layers, fallback_lower=fallback[0], fallback_upper=fallback[1],
                   eta=eta, precision=s.precision, complement=complement and not minimum,
                   trim=mdp.n_transitions >= TRIM_FROM_TRANSITIONS)
    checks.extend(cert.checks)
    return ModelSolution(which, status, value, policy, read_only(np.asarray(cert.values)),
                         (it.value_lower, it.value_upper), lp, it, decided.unreachable,
                         tuple(checks), sense, (cert.lower, cert.upper), decided)


def _lp_policy(lp: LPResult | None) -> bool:
    """Whether the model's answer is the LP's policy (else the iteration's)."""
    from mitld_lp.solvers.result import Status

    return lp is not None and lp.status is Status.OPTIMAL and lp.policy is not None


def _settled(it: IterationResult, lp: LPResult | None) -> IterationResult:
    """``it`` as the certificate reads it, before the model's quotient is released: its
    policy made where the answer is the iteration's (the LP gave none), else let go
    unread with the quotient its function holds (:attr:`IterationResult.policy`)."""
    if _lp_policy(lp):
        return it.without_greedy()
    it.policy  # noqa: B018 - made now, while the quotient lives
    return it


def _read_by_certificate(it: IterationResult, sense: str,
                         ) -> tuple[np.ndarray | Lifted, np.ndarray | Lifted | None]:
    """The iteration's bounds the certificate reads (:func:`mitld_lp.solvers.certify.
    certify`) as the record holds them: on the quotient
    (:class:`~mitld_lp.solvers.result.Lifted`), each read where the certificate reads
    it (the chain's guess on its solved states, a candidate's fallback on its states),
    never lifted whole: the lower one (the chain's guess, and a minimum's bound from
    below), the upper one for a maximum (its bound from above; a minimum's certificate
    reads none)."""
    return it.held_lower, (it.held_upper if sense == "max" else None)


def _trimmed(mdp: MDP, lp: LPResult | None) -> LPResult | None:
    """``lp``, the heap's free pages handed back to the system first for a product of
    at least :data:`TRIM_FROM_TRANSITIONS` (:mod:`mitld_lp.util.heap`): an LP's freed
    temporaries are holes the next LP and the certificates only partly fill.  On issue
    45's sensed case (1.08M transitions, two LPs) the solve's resident peak, at the LPs'
    ends, went from 112 to 103 bytes a transition (experiments/bench_qvbs.py); trimming
    after the interval iteration as well freed nothing at peak (the first LP fills
    those pages again)."""
    if mdp.n_transitions >= TRIM_FROM_TRANSITIONS:
        heap.release_free_memory()
    return lp


def _iterate(mdp: MDP, quotients: list[Quotient], s: Settings,
             deadline: Deadline) -> list[IterationResult]:
    """Interval iteration of the models in one pass over their shared quotient.  When the
    graph analysis decides the initial state, every component is still brought below the
    tolerance (``gap="max"``), as the LP then solves every state (``everywhere``): the
    certified policy is optimal in every state the Bellman check reads, not only where
    the initial state leads."""
    from mitld_lp.solvers.iteration import interval_iterations

    decided = quotients[0].initial < 0
    # the relative precision where the bracket is the answer's (the initial state);
    # when the graph decides that, the LP solves every state and the bounds only prune
    return interval_iterations(mdp, quotients, tol=s.tol,
                               precision=None if decided else s.precision,
                               progress=s.progress, time_limit=deadline.left(),
                               gap="max" if decided or s.method == "vi" else "initial")


def _keeping(mdp: MDP, accept: Acceptance, solution: ModelSolution) -> ModelSolution:
    """For a task with a safety part: ``solution`` whose policy plays, in the accepting
    end components, an internal choice (never one that can leave them), with the check
    that no state of them escapes under the policy.  Unchanged for a co-safe task."""
    if accept.components is None:
        return solution
    from mitld_lp.solvers.accepting import escapes, keep_inside

    policy = keep_inside(accept.components, solution.policy)
    leaving = np.flatnonzero(escapes(mdp, policy, accept.goal))
    check = Check(
        "policy stays in the accepting end components",
        leaving.size == 0,
        f"{int(accept.goal.sum())} states in {accept.components.mecs.n_mecs} components; "
        + (f"states {leaving[:10].tolist()} can leave" if leaving.size else "none can leave"),
    )
    return replace(solution, policy=policy, checks=(*solution.checks, check))


def solve_models(mdp: MDP, accept: Acceptance, s: Settings, t0: float,
                 sense: str = "max", eta: float | None = None, *,
                 complement: bool = False) -> tuple[ModelSolution, ModelSolution]:
    """Both truncation models of ``mdp`` solved and certified (module docs) for the
    target ``accept`` (its goal; a task's accepting end components kept by their
    choices), with the settings ``s`` of a posed problem, the time limit counted from
    ``t0``, maximised (``sense="min"``: minimised).  ``eta``: the probabilities'
    allowance (default :data:`mitld_lp.solvers.certify.ETA`); ``complement``: the answer
    is read back as ``1 -`` the values (the precision is relative to that).  Returned as
    (the controller's model, the bound's model): for a maximum the lower model then the
    upper one, for a minimum the upper then the lower (module docs).  The two are one
    object when nothing is truncated."""
    from mitld_lp.solvers.analysis import analyse
    from mitld_lp.solvers.certify import ETA
    from mitld_lp.solvers.graph import Sense

    deadline = Deadline.after(s.time_limit, t0)
    # The builder's freed temporaries go back to the system (mitld_lp.util.heap): every
    # route's product (the plain one, the sensed information states) is solved here.
    if mdp.n_transitions >= TRIM_FROM_TRANSITIONS:
        release_free_memory()
    quotients = analyse(mdp, accept.goal, mdp.truncated, sense=Sense(sense))
    quotients = quotients[:1] if quotients[1] is quotients[0] else list(quotients)
    its = _iterate(mdp, quotients, s, deadline)
    # and the analysis's and iteration's freed temporaries before the LPs of a large
    # product: the LP's factorisations (SuperLU's, kept for the certificates) filled
    # those holes only in part, and its end was the resident peak on bus_scaled d3
    # (:data:`TRIM_BEFORE_LP_FROM`)
    if mdp.n_transitions >= TRIM_BEFORE_LP_FROM:
        release_free_memory()
    # (each LP's freed pages handed back before the next stage: _trimmed)
    # the controller's model (below: the upper one of a minimum's two) alone makes
    # its LP's primal point, the one primal objective read (report.models_summary)
    mine = 1 if Sense(sense) is Sense.MIN and len(quotients) == 2 else 0
    lps = [_trimmed(mdp, _solve_lp(mdp, q, it, s, deadline,
                                   quotients[k + 1] if k + 1 < len(quotients) else None,
                                   primal=k == mine))
           for k, (q, it) in enumerate(zip(quotients, its, strict=True))]
    # The certificates work on the product: the reduced matrix (a second copy of most
    # transitions) is released before the exact evaluations, where memory peaks.
    # (a minimum's certificate reads no end components: its quotient has none, and
    # their map, an index a state, is not held through the certificates)
    kept = [(np.asarray(q.target), q.qualitative, q.layers,
             None if q.sense is Sense.MIN else q.mecs.mec_of) for q in quotients]
    its = [_settled(it, lp) for it, lp in zip(its, lps, strict=True)]
    # the records hold their bounds and values as the quotient's (a float a reduced
    # state: Lifted); the certificate's are lifted as it reads them
    held = list(zip(its, lps, strict=True))
    del quotients, its, lps
    eta = ETA if eta is None else eta
    solutions = [_certified(mdp, *k, it, lp, which, s, eta, complement,
                            _read_by_certificate(it, str(k[1].sense)))
                 for k, (it, lp), which in zip(kept, held, ("lower", "upper"), strict=False)]
    low, high = solutions[0], solutions[-1]  # one model when nothing is truncated
    if Sense(sense) is Sense.MIN:  # the controller plays the upper model's policy
        low, high = high, low
    kept_low = _keeping(mdp, accept, low)
    return kept_low, (kept_low if high is low else high)


def _exact(posed: Posed, built: Built, accept: Acceptance, low: ModelSolution,
           high: ModelSolution, t0: float,
           ) -> tuple[dict[str, Any], ModelSolution, ModelSolution]:
    """The exact answer (:func:`mitld_lp.exact.exact_answer`) as the result's fields (the
    exact record; past the time limit the status) and the models (the controller's, the
    bound's: :func:`solve_models`) with their exact-optimal policies, each model's
    ``bounds`` its exact optimum rounded outward.  The exact check proves the bracket:
    it takes the place of the float certificate's checks (the float bounds and the
    policy's optimality in every state, now shown exactly).  A minimum is the task's own
    (``built.sense == "min"``) or the complement's maximum read back (a task with a safety
    part: :func:`mitld_lp.routes.stages.build_posed`)."""
    from mitld_lp.exact.stage import exact_answer
    from mitld_lp.solvers.certify import float_down, float_up, is_certificate_check
    from mitld_lp.solvers.result import Status

    s = posed.settings
    deadline = Deadline.after(s.time_limit, t0)
    minimum = built.sense == "min"
    complemented = posed.minimise and not minimum
    # exact_answer takes the truncation models in their order (lower, upper); for a
    # minimum solve_models hands the upper one (the controller's) first
    lower_trunc, upper_trunc = (high, low) if minimum else (low, high)
    answer, (exact_lower, exact_upper), check = exact_answer(
        built.mdp, posed.model.game, built.sta, (lower_trunc, upper_trunc), accept.goal,
        sense=built.sense, complemented=complemented, deadline=deadline.at)
    if answer is None:  # the float certificate stands, the exact check failed
        first = replace(low, checks=(*low.checks, check))
        return {"status": Status.TIME_LIMIT}, first, (first if high is low else high)
    # each truncation model's optimum in its own terms (the complement's for a minimum
    # read back), the lower model's the answer's lower end
    optima = (1 - answer.upper, 1 - answer.lower) if complemented else (answer.lower,
                                                                        answer.upper)
    exact_lower, exact_upper = (
        replace(m, bounds=(float_down(q), float_up(q)),
                checks=tuple(c for c in m.checks if not is_certificate_check(c)))
        for m, q in zip((exact_lower, exact_upper), optima, strict=True))
    first, second = (exact_upper, exact_lower) if minimum else (exact_lower, exact_upper)
    first = replace(first, checks=(*first.checks, check))
    return {"exact": answer}, first, (first if high is low else second)


def solve_plain(posed: Posed, built: Built) -> Result:
    """The plain route: point laws, no constraints, any supported task class."""
    from mitld_lp.routes.acceptance import acceptance

    model, s = posed.model, posed.settings
    eps = model.epsilon if s.epsilon is None else s.epsilon
    mdp = built.mdp
    timings: dict[str, float] = dict(built.timings)
    t0, c0 = time.perf_counter(), time.process_time()
    from mitld_lp.solvers.certify import model_eta

    accept = acceptance(mdp, built.dta)
    low, high = solve_models(mdp, accept, s, t0, built.sense, model_eta(built.sta),
                             complement=posed.minimise and built.sense == "max")
    timings["solve"] = time.perf_counter() - t0
    fields: dict[str, Any] = {}
    if s.exact:  # the optimum as a fraction (mitld_lp.exact), its policy the controller's
        fields, low, high = _exact(posed, built, accept, low, high, t0)
        timings["exact"] = time.perf_counter() - t0 - timings["solve"]
    solve_cpu = time.process_time() - c0
    # the controller plays the first model's policy (solve_models): the one whose value
    # the answer's near end bounds; it stops where the task cannot happen even if every
    # truncated event came in time: the upper model's unreachable states
    upper = low if built.sense == "min" else high
    result = Result(
        route=PlainRoute.name, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=built.sta, mdp=mdp, dta=built.dta,
        controller=Controller(model.game, built.sta, mdp, low.policy, hopeless=upper.prob0),
        timings=timings, part=PlainPart(low, high, accept), solve_cpu=solve_cpu,
        **{**from_models(low, high, mdp.initial, posed.problem.objective, s.precision,
                         truncated=bool(mdp.truncated.any()), sense=built.sense,
                         exact=fields.get("exact")),
           **fields})
    log.info("synthesis: %s, certified=%s",  # outward, as every surface prints it
             bracket_text(result.lower, result.upper), result.certified)
    return result


@dataclass(frozen=True, slots=True, eq=False)
class PlainPart(Part):
    """The plain route's part of the answer: the two solved models (the controller's,
    the bound's: :func:`solve_models`) and the target the bracket is about; the policy
    keeps a task's safety part in its accepting end components."""

    lower_model: ModelSolution = field()  # required (Part's default is for the other routes)
    upper_model: ModelSolution = field()
    acceptance: Acceptance = field()
    kept_components = True


class PlainRoute(Route):
    """Point laws, no constraints, every sensor perfect: any supported task class
    (co-safe, safety, obligation), both truncation models solved and certified; the one
    route with an exact answer (:mod:`mitld_lp.exact`)."""

    name = "plain"
    exact = True

    def claims(self, posed: Posed) -> bool:
        return not (posed.robust or posed.problem.constrained or posed.sensed)

    def refusal(self, posed: Posed) -> list[str]:
        from mitld_lp.logic.fragment import CO_SAFE, OBLIGATION, SAFETY

        refused = [f"plain route: {why}" for why in posed.beyond_points().values()]
        if posed.fragment not in (CO_SAFE, SAFETY, OBLIGATION):  # check() refuses others
            refused.append(f"{task_words(posed.fragment, posed.problem.objective)}: "
                           "not a supported class")
        return refused

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        return build_task(posed, progress)

    def solve(self, posed: Posed, built: Built, *, costs: Any = None,
              seed: int | None = 0) -> Result:
        return solve_plain(posed, built)
