"""``synthesize``: the one place that wires the stages.

    spec --to_dta--> DTA --make_sta--> STA --product(game)--> MDP --solve--> policy

The product is built once; its truncation sink counted as losing gives the *lower*
model, as winning the *upper* model.  Each model is solved (occupancy LP or interval
iteration) and certified:

* the extracted deterministic policy is evaluated exactly on its Markov chain (sparse
  solve): a value the policy really achieves;
* interval iteration gives sound lower and upper bounds on the optimum;
* with the LP, its primal objective, its dual objective (the value function at the
  initial state), the policy's value and the iteration bracket must agree within
  ``certify_tol``.

``lower`` is the exact value of the returned policy in the lower model (truncation
counted as failure): the policy achieves at least that in the real, untruncated world.
``upper`` is the sound upper bound of interval iteration on the upper model: no policy
does better.  So the true optimum lies in ``[lower, upper]``, and
``upper - lower <= epsilon_achieved`` up to the solver tolerance.
"""

from __future__ import annotations

import csv
import json
import logging
import os
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from mitld_lp import defaults
from mitld_lp.automata.dta import DTA
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.controller import Controller
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.game import Game
from mitld_lp.logic.syntax import Formula
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.product import product
from mitld_lp.solvers.iteration import evaluate_policy, interval_iteration
from mitld_lp.solvers.lp import solve_lp
from mitld_lp.solvers.quotient import Quotient, reduce
from mitld_lp.solvers.result import IterationResult, LPResult, Status

if TYPE_CHECKING:
    from mitld_lp.constrained import ConstrainedResult

__all__ = ["synthesize", "build_product", "Built", "SynthesisResult", "ModelSolution", "Check",
           "Sizes"]

log = logging.getLogger(__name__)

_POLICY_COLUMNS = ("game_state", "automaton_state", "pending", "clock", "action", "value")

Method = Literal["lp", "vi"]


@dataclass(frozen=True, slots=True)
class Check:
    """One certification check: what was compared, whether it passed, the numbers."""

    name: str
    passed: bool
    detail: str


@dataclass(frozen=True, slots=True, eq=False)
class ModelSolution:
    """The solution of one of the two models (lower: truncation loses; upper: it wins)."""

    which: str
    status: Status
    value: float  # the method's optimum at the initial state
    policy: np.ndarray  # deterministic: a choice row per state, -1 where absorbing
    policy_value: float  # exact value of ``policy`` at the initial state
    bracket: tuple[float, float]  # interval iteration's sound bounds at the initial state
    lp: LPResult | None
    iteration: IterationResult
    quotient: Quotient  # the reduction both solvers worked on (its prob0: no hope)
    checks: tuple[Check, ...]

    @property
    def certified(self) -> bool:
        return all(c.passed for c in self.checks)


@dataclass(frozen=True, slots=True)
class Sizes:
    dta_states: int
    states: int
    choices: int
    transitions: int


@dataclass(frozen=True, slots=True, eq=False)
class SynthesisResult:
    """What :func:`synthesize` returns (see the module docstring for the bracket).

    ``status`` is ``OPTIMAL`` when every solve succeeded; ``certified`` tells whether all
    checks passed, and ``failed_checks`` which did not.
    """

    status: Status
    lower: float
    upper: float
    value: float
    certified: bool
    method: str
    policy: np.ndarray
    randomized: np.ndarray | None
    controller: Controller
    epsilon: float
    epsilon_achieved: float
    truncation_points: Mapping[str, int]
    sizes: Sizes
    timings: Mapping[str, float]
    lower_model: ModelSolution
    upper_model: ModelSolution
    dta: DTA
    sta: STA
    mdp: MDP
    model: Model

    @property
    def failed_checks(self) -> tuple[Check, ...]:
        return tuple(
            c for m in (self.lower_model, self.upper_model) for c in m.checks if not c.passed
        )

    @property
    def seconds(self) -> float:
        return float(sum(self.timings.values()))

    def __repr__(self) -> str:
        return (
            f"SynthesisResult(model={self.model.name!r}, lower={self.lower:.7g}, "
            f"upper={self.upper:.7g}, certified={self.certified}, "
            f"status={self.status.value!r}, states={self.sizes.states})"
        )

    def _repr_html_(self) -> str:
        from html import escape

        rows = [
            ("model", self.model.name),
            ("spec", str(self.model.spec)),
            ("optimum in", f"[{self.lower:.7f}, {self.upper:.7f}]"),
            ("certified", "yes" if self.certified else "NO: " + "; ".join(
                c.name for c in self.failed_checks)),
            ("status", self.status.value),
            ("epsilon achieved", f"{self.epsilon_achieved:.3g}"),
            ("sizes", f"{self.sizes.dta_states} automaton states, {self.sizes.states} "
                      f"states, {self.sizes.transitions} transitions"),
        ]
        body = "".join(
            f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
            for k, v in rows
        )
        return f"<table>{body}</table>"

    def policy_table(self) -> list[dict[str, Any]]:
        """The policy as data: one row per product state that is still undecided.

        Keys: ``game_state`` (the game's own state), ``automaton_state`` (the obligation
        still to satisfy, as formula text), ``pending`` (the events that have not
        happened, sorted), ``clock`` (steps counted for the pending events, capped where
        their hazards stop changing), ``action`` (the policy's action), ``value`` (the
        probability that the policy satisfies the task from there, truncation counted as
        failure: exact, from a linear solve on the policy's Markov chain).
        """
        from mitld_lp.product import ProductState
        from mitld_lp.solvers.iteration import evaluate_policy

        mdp, policy = self.mdp, self.policy
        values = evaluate_policy(mdp, mdp.target, policy)
        obligations = self.dta.states
        rows: list[dict[str, Any]] = []
        for i, state in enumerate(mdp.states):
            if not isinstance(state, ProductState) or policy[i] < 0:
                continue
            rows.append({
                "game_state": state.game,
                "automaton_state": str(obligations[state.automaton]),
                "pending": sorted(state.pending),
                "clock": state.clock,
                "action": mdp.action_name(int(policy[i])),
                "value": float(values[i]),
            })
        return rows

    def write_policy(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write :meth:`policy_table` to ``path``: ``.csv`` (one row per state, pending
        events joined by spaces) or ``.json`` (a list of objects).  Refuses to replace an
        existing file unless ``overwrite``."""
        out = Path(path)
        suffix = out.suffix.lower()
        if suffix not in (".csv", ".json"):
            raise ValueError(f"{out}: the suffix must be .csv or .json")
        if out.exists() and not overwrite:
            raise FileExistsError(f"{out}: exists; pass overwrite=True to replace it")
        rows = self.policy_table()
        if suffix == ".json":
            out.write_text(json.dumps(rows, default=str) + "\n")
            return out
        with out.open("w", newline="") as handle:
            writer: csv.DictWriter[str] = csv.DictWriter(handle, fieldnames=list(_POLICY_COLUMNS))
            writer.writeheader()
            for row in rows:
                writer.writerow({**row, "game_state": str(row["game_state"]),
                                 "pending": " ".join(row["pending"]),
                                 "value": repr(row["value"])})
        return out

    def summary(self) -> dict[str, Any]:
        """A JSON-ready record (the CLI's ``--json``)."""
        return {
            "model": self.model.name,
            "status": self.status.value,
            "lower": self.lower,
            "upper": self.upper,
            "value": self.value,
            "certified": self.certified,
            "failed_checks": [f"{c.name}: {c.detail}" for c in self.failed_checks],
            "method": self.method,
            "states": self.sizes.states,
            "choices": self.sizes.choices,
            "transitions": self.sizes.transitions,
            "dta_states": self.sizes.dta_states,
            "epsilon": self.epsilon,
            "epsilon_achieved": self.epsilon_achieved,
            "truncation_points": dict(self.truncation_points),
            "seconds": self.seconds,
            "timings": dict(self.timings),
            "lp": None
            if self.lower_model.lp is None
            else {
                "status": self.lower_model.lp.status.value,
                "solver": self.lower_model.lp.solver,
                "backend": self.lower_model.lp.backend,
                "primal_objective": self.lower_model.lp.primal_objective,
                "dual_objective": self.lower_model.lp.dual_objective,
                "iterations": self.lower_model.lp.iterations,
                "seconds": self.lower_model.lp.seconds,
                "message": self.lower_model.lp.message,
            },
            "iteration": {
                "status": self.lower_model.iteration.status.value,
                "lower": self.lower_model.iteration.value_lower,
                "upper": self.upper_model.iteration.value_upper,
                "iterations": self.lower_model.iteration.iterations,
            },
        }


def _close(name: str, a: float, b: float, tol: float) -> Check:
    ok = bool(np.isfinite(a) and np.isfinite(b) and abs(a - b) <= tol)
    return Check(name, ok, f"{a:.10g} vs {b:.10g} (|diff| = {abs(a - b):.2e}, tol {tol:g})")


_NUMERICAL = (Status.INACCURATE, Status.MAX_ITERATIONS)
"""LP outcomes that the interval-iteration policy may stand in for."""


def _solve_model(
    mdp: MDP,
    target: np.ndarray,
    which: str,
    *,
    method: Method,
    solver: str,
    backend: str,
    tol: float,
    certify_tol: float,
    progress: bool,
    decompose: bool = True,
    deadline: float = float("inf"),
) -> ModelSolution:
    """Solve one model by ``method`` and certify it (module docs).

    The model is reduced once and every solver works on that :class:`Quotient`.  An LP
    that does not come back optimal (after its own retries) is replaced by the
    interval-iteration policy, certified the same way (exact value inside the bracket).
    """
    quotient = reduce(mdp, target)

    def remaining() -> float | None:
        return None if deadline == float("inf") else max(0.0, deadline - time.perf_counter())

    it = interval_iteration(mdp, target, quotient=quotient, tol=tol, progress=progress,
                            time_limit=remaining())
    checks = [
        Check("iteration converged", it.status is Status.OPTIMAL, it.message),
    ]
    lp: LPResult | None = None
    policy, value, status = it.policy, it.value_lower, it.status
    if method == "lp":
        lp = solve_lp(mdp, target, quotient=quotient, solver=solver, backend=backend,  # type: ignore[arg-type]
                      tol=tol, decompose=decompose, time_limit=remaining())
        if lp.status is Status.OPTIMAL and lp.policy is not None:
            policy, value, status = lp.policy, lp.value, lp.status
            checks.append(Check("LP solved", True, f"{lp.status.value}: {lp.message}"))
            checks.append(_close("LP primal = dual", lp.primal_objective, lp.dual_objective,
                                 certify_tol))
        elif lp.status in _NUMERICAL and it.status is Status.OPTIMAL:
            # A numerical failure after the LP's own retries: the answer is the converged
            # iteration's, certified below like method "vi"; the LP's word is kept.
            checks.append(Check("LP replaced by the iteration policy", True,
                                f"{lp.status.value}: {lp.message}"))
        else:  # a usage error (solver not installed), a time limit, or no fallback
            status = lp.status
            checks.append(Check("LP solved", False, f"{lp.status.value}: {lp.message}"))
    exact = float(evaluate_policy(mdp, target, policy)[mdp.initial])
    lo, hi = it.value_lower, it.value_upper
    checks.append(Check(
        "policy value within iteration bracket",
        lo - certify_tol <= exact <= hi + certify_tol,
        f"policy {exact:.10g} in [{lo:.10g}, {hi:.10g}] +- {certify_tol:g}",
    ))
    checks.append(_close("policy value = optimum", exact, value, certify_tol))
    checks.append(_close("optimum = iteration upper bound", value, hi, certify_tol))
    return ModelSolution(which, status, value, policy, exact, (lo, hi), lp, it, quotient,
                         tuple(checks))


@dataclass(frozen=True, slots=True, eq=False)
class Built:
    """What :func:`build_product` returns: the automaton, the STA and the product MDP,
    with the seconds each construction took (``automaton``, ``product``)."""

    dta: DTA
    sta: STA
    mdp: MDP
    timings: Mapping[str, float]


def build_product(
    game: Game[Any],
    formula: Formula,
    laws: Mapping[str, FirstOccurrence],
    *,
    epsilon: float = defaults.EPSILON,
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    progress: bool | None = None,
) -> Built:
    """The stages up to the MDP: ``to_dta(formula)``, ``make_sta`` with the events'
    ``laws`` and the truncation budget ``epsilon`` (or the fixed ``truncation`` points),
    then the reachable ``product`` with ``game``; the automaton and the product each
    within ``max_states`` states, the product also within
    ``max_memory`` bytes (default: half the machine's memory), both checked before the
    work that would exceed them.  The only place that wires the stages."""
    t0 = time.perf_counter()
    dta = to_dta(formula, max_states=max_states)
    sta = make_sta(dta, laws, epsilon, clock_reduction=clock_reduction, truncation=truncation)
    t1 = time.perf_counter()
    mdp = product(game, sta, max_states=max_states, max_memory=max_memory, progress=progress)
    t2 = time.perf_counter()
    return Built(dta, sta, mdp, {"automaton": t1 - t0, "product": t2 - t1})


def synthesize(
    model: Model,
    *,
    epsilon: float | None = None,
    method: Method = "lp",
    solver: str = "CLARABEL",
    backend: str = "auto",
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
    max_states: int = defaults.MAX_STATES,
    max_memory: int | None = None,
    tol: float = defaults.TOL,
    certify_tol: float = defaults.CERTIFY_TOL,
    progress: bool = False,
    decompose: bool = True,
    time_limit: float | None = None,
    constraints: Iterable[Any] = (),
    then: str | None = None,
) -> SynthesisResult | ConstrainedResult:
    """Maximise the probability that the model's world satisfies its MITLD spec.

    ``model``: a :class:`Model`, loaded from a file (:func:`mitld_lp.load_model`) or
    made from any game with :meth:`Model.from_game`; ``epsilon`` overrides its
    truncation budget.  ``method``: ``"lp"`` (occupancy LP through Clarabel, called
    directly, or through cvxpy with ``backend="cvxpy"``, which also takes any other
    ``solver`` cvxpy has) or ``"vi"`` (interval iteration alone).  Interval
    iteration always runs, as the cross-check.  ``truncation`` fixes truncation points
    per event instead of ``epsilon``.
    ``decompose``: the LP block by block in topological order (default) or as one LP.
    ``time_limit``: seconds for the solve stage; past it the status is ``TIME_LIMIT``.
    ``constraints`` / ``then`` (or constraints in the model): a constrained synthesis,
    :func:`mitld_lp.constrained.synthesize_constrained`, whose result it returns.
    """
    if constraints or then or (isinstance(model, Model) and model.constraints):
        from mitld_lp.constrained import synthesize_constrained

        return synthesize_constrained(model, constraints, then=then, epsilon=epsilon,
                                      max_states=max_states, max_memory=max_memory,
                                      certify_tol=certify_tol)
    if method not in ("lp", "vi"):
        raise ValueError(f"method: must be 'lp' or 'vi', got {method!r}")
    if not isinstance(model, Model):
        raise TypeError(
            f"synthesize: expected a Model (load_model(path) or Model.from_game(game, spec)), "
            f"got {type(model).__name__}"
        )
    eps = model.epsilon if epsilon is None else epsilon
    built = build_product(
        model.game, model.spec, model.distributions, epsilon=eps,
        clock_reduction=clock_reduction, truncation=truncation, max_states=max_states,
        max_memory=max_memory, progress=progress or None,
    )
    dta, sta, mdp = built.dta, built.sta, built.mdp
    timings: dict[str, float] = dict(built.timings)

    t0 = time.perf_counter()
    common = dict(method=method, solver=solver, backend=backend, tol=tol,
                  certify_tol=certify_tol, progress=progress, decompose=decompose,
                  deadline=float("inf") if time_limit is None else t0 + time_limit)
    low = _solve_model(mdp, mdp.target, "lower", **common)  # type: ignore[arg-type]
    if mdp.truncated.any():
        high = _solve_model(mdp, mdp.target | mdp.truncated, "upper", **common)  # type: ignore[arg-type]
    else:
        high = low
    timings["solve"] = time.perf_counter() - t0

    statuses = {low.status, high.status}
    status = Status.OPTIMAL if statuses == {Status.OPTIMAL} else next(
        s for s in (low.status, high.status) if s is not Status.OPTIMAL)
    randomized = low.lp.randomized if low.lp is not None else None
    result = SynthesisResult(
        status=status,
        lower=low.policy_value,
        upper=high.bracket[1],
        value=low.value,
        certified=low.certified and high.certified,
        method=method,
        policy=low.policy,
        randomized=randomized,
        controller=Controller(model.game, sta, mdp, low.policy,
                              hopeless=high.quotient.prob0),
        epsilon=eps,
        epsilon_achieved=sta.epsilon_achieved,
        truncation_points=sta.truncation_points,
        sizes=Sizes(dta.n_states, mdp.n_states, mdp.n_choices, mdp.n_transitions),
        timings=timings,
        lower_model=low,
        upper_model=high,
        dta=dta,
        sta=sta,
        mdp=mdp,
        model=model,
    )
    log.info("synthesis: [%g, %g], certified=%s", result.lower, result.upper, result.certified)
    return result
