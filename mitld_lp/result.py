"""The one answer of every route: :class:`Result`.

Whatever route a posed problem takes (:mod:`mitld_lp.problem`: plain, robust for a
law known within a band, constrained), :func:`mitld_lp.synthesize` returns a
:class:`Result`: one status vocabulary (:class:`~mitld_lp.solvers.result.Status`), the
certified bracket ``[lower, upper]``, ``certified`` and the ``checks`` it rests on, the
``controller`` (deterministic or randomised, one interface), the sizes and the timings;
and the parts only some routes have: the two solved models (``lower_model``,
``upper_model``) where the optimum comes from a deterministic policy, the bands
(``bands``, ``first_step_hazards()``), the constraints' part (``constraints``, ``then``,
``secondary``, ``steps``, the randomised policy ``prob`` / ``stay`` on the ``merged``
model of the ``joint`` automaton), the sensors' part (``sensors``, the information-state
product ``belief``; the ``mdp`` is then that product).  A part a route does not have
is ``None`` or empty.
``summary()`` is the command line's ``--json``, one schema for every route
(:data:`mitld_lp.report.SUMMARY_KEYS`).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mitld_lp import report
from mitld_lp.checks import Check

if TYPE_CHECKING:
    from mitld_lp.automata.dta import DTA
    from mitld_lp.automata.sta import STA
    from mitld_lp.model import Model
    from mitld_lp.solvers.result import Status

__all__ = ["Result", "SynthesisResult", "from_models", "precision_check"]


@dataclass(frozen=True, slots=True, eq=False)
class Result:
    """What :func:`mitld_lp.synthesize` returns on every route (module docs).

    ``lower``: what the returned controller achieves in the real, untruncated world
    (for a band, whatever law of the band the events follow; with constraints, each
    constraint holding); ``upper``: what no policy beats; the optimum lies in between.
    Both hold in exact arithmetic for the model as written, its decimal probabilities
    (:mod:`mitld_lp.solvers.certify`).  For ``objective="min"`` both are in the task's
    terms: ``upper`` is then what the controller guarantees at most, ``lower`` what no
    policy goes below; read back from the complement (``Pmin(task) = 1 - Pmax(not
    task)``), ``complement`` is the complement's bracket.  ``value``: the method's
    optimum (the lower model's).  ``checks``: every certification check, each once;
    ``certified``: all passed.  ``mdp``: the model the solver worked on (an interval MDP
    for a band; for constraints the product, ``merged`` the model the LP solved).
    """

    route: str  # "plain", "robust", "constrained" or "sensed" (mitld_lp.problem)
    model: Model | None
    objective: str  # "max" or "min"
    method: str  # "lp" or "vi"
    epsilon: float  # the truncation budget asked for
    status: Status
    lower: float
    upper: float
    value: float
    certified: bool
    checks: tuple[Check, ...]
    controller: Any  # a ControllerLike: Controller or ConstrainedController; None if unsolved
    sta: STA
    mdp: Any
    timings: Mapping[str, float]  # seconds per stage
    solve_cpu: float = float("nan")  # CPU seconds of the solve stage (all threads)
    dta: DTA | None = None  # the task's automaton (its complement for "min")
    # the two solved models (plain and robust routes)
    lower_model: Any = None
    upper_model: Any = None
    acceptance: Any = None  # the target the bracket is about (its goal, its components)
    goal: np.ndarray | None = None  # robust: the states that satisfy the task robustly
    # laws known within a band: each such event and its law's label
    bands: Mapping[str, str] = field(default_factory=dict)
    # the constraints' part
    constraints: tuple[Any, ...] = ()  # ConstraintValue records
    then: str | None = None
    secondary: float | None = None
    steps: float = float("nan")  # expected steps of the returned policy
    message: str = ""
    merged: Any = None
    joint: Any = None
    prob: np.ndarray | None = None  # per merged choice: the policy's probability
    stay: np.ndarray | None = None  # per merged state: the probability of staying
    # sensors that miss events: each sensed event's sensor, the information-state product
    sensors: Mapping[str, Any] = field(default_factory=dict)
    belief: Any = None
    # the certificate's parts: for a minimum read back from the complement's maximum,
    # the complement's own bracket (1 - the task's probability lies in it, kept with its
    # digits where the task's bracket rounds to 1); the relative precision asked; the
    # bracket's width split into the truncation's part (the two models' optima apart)
    # and the solver's (the certificates' slack)
    complement: tuple[float, float] | None = None
    precision: float = float("nan")
    width: Mapping[str, float] = field(default_factory=dict)

    @property
    def failed_checks(self) -> tuple[Check, ...]:
        """The checks that failed."""
        return tuple(c for c in self.checks if not c.passed)

    @property
    def seconds(self) -> float:
        return float(sum(self.timings.values()))

    @property
    def imdp(self) -> Any:
        """The interval MDP of a robust answer (``mdp``); ``None`` on other routes."""
        return self.mdp if self.route == "robust" else None

    @property
    def automaton(self) -> DTA:
        """The automaton the product was built from (the joint one with constraints)."""
        if self.dta is not None:
            return self.dta
        return self.joint.dta

    @property
    def randomized_states(self) -> int:
        """How many states a randomised (constrained) policy randomises in."""
        if self.prob is None or self.stay is None:
            return 0
        cs = self.merged.mdp.choice_state()
        positive = np.bincount(cs, weights=(self.prob > 0).astype(float),
                               minlength=self.merged.mdp.n_states) + (self.stay > 0)
        return int(np.count_nonzero(positive > 1))

    def first_step_hazards(self) -> dict[str, tuple[float, float]]:
        """Each event with a band: ``(h_lo(1), h_hi(1))``, how much its band leaves open
        at the first step (wide for a fit from few observations)."""
        out = {}
        for e, c in sorted(self.sta.clocks.items()):
            if c.distribution.is_ambiguous:
                lo, hi = c.distribution.hazard_band(1)
                out[e] = (float(lo), float(hi))
        return out

    def __repr__(self) -> str:
        name = None if self.model is None else self.model.name
        lower, upper = report.bracket_text(self.lower, self.upper)[1:-1].split(", ")
        return (f"Result(route={self.route!r}, model={name!r}, lower={lower}, "
                f"upper={upper}, certified={self.certified}, "
                f"status={str(self.status)!r}, states={self.mdp.n_states})")

    def _repr_html_(self) -> str:
        return report.html(self)

    def policy_table(self) -> list[dict[str, Any]]:
        """The policy as data (:func:`mitld_lp.report.policy_table`)."""
        return report.policy_table(self)

    def write_policy(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write :meth:`policy_table` to ``path`` (:func:`mitld_lp.files.write.write_policy`)."""
        from mitld_lp.files.write import write_policy

        return write_policy(self, path, overwrite=overwrite)

    def summary(self) -> dict[str, Any]:
        """A JSON-ready record, the CLI's ``--json`` (:func:`mitld_lp.report.summary`)."""
        return report.summary(self)


#: The name of earlier releases, for code that imports it: the same class.
SynthesisResult = Result


def from_models(lower_model: Any, upper_model: Any, initial: int, objective: str,
                precision: float = float("nan"), *, truncated: bool = False,
                ) -> dict[str, Any]:
    """The answer's fields read from two solved models (plain and robust routes): the
    lower model's certified lower bound and the upper model's certified upper bound
    (``bounds``), in the task's terms (a minimum solved as the complement's maximum is
    read back, rounded outward, with the complement's bracket kept); the status is
    ``OPTIMAL`` when both solves succeeded, else the first other; every check once (the
    two models are one when nothing is truncated; otherwise each check's name says
    which model it checked), and the check that the solver's part of the width is
    within ``precision`` of the value (``truncated``: the two models differ by the
    truncation, whose part of the width is reported apart)."""
    from mitld_lp.solvers.certify import one_minus
    from mitld_lp.solvers.result import Status

    low, high = float(lower_model.bounds[0]), float(upper_model.bounds[1])
    models = (lower_model,) if upper_model is lower_model else (lower_model, upper_model)
    complement = None
    if objective == "min" and getattr(lower_model, "sense", "max") == "max":
        complement = (low, high)
        (lower, upper), value = one_minus(low, high), 1.0 - lower_model.value
    else:
        lower, upper, value = low, high, lower_model.value
    # the estimates of the two models' optima: how far apart the truncation sets them
    apart = abs(float(upper_model.policy_values[initial])
                - float(lower_model.policy_values[initial])) if truncated else 0.0
    total = upper - lower
    solver = max(total - apart, 0.0)
    checks = [c if len(models) == 1 else Check(f"{m.which} model: {c.name}", c.passed, c.detail)
              for m in models for c in m.checks]
    checks.append(precision_check(lower, upper, solver, apart, precision))
    return {
        "lower": lower, "upper": upper, "value": float(value),
        "status": next((m.status for m in models if m.status is not Status.OPTIMAL),
                       Status.OPTIMAL),
        "certified": all(c.passed for c in checks),
        "checks": tuple(checks),
        "lower_model": lower_model, "upper_model": upper_model,
        "complement": complement, "precision": precision,
        "width": {"total": total, "truncation": apart, "solver": solver},
    }


def precision_check(lower: float, upper: float, solver: float, truncation: float,
                    precision: float) -> Check:
    """The check that the solver's part ``solver`` of the bracket's width is at most
    ``precision`` times the value (``lower``); the truncation's part is reported."""
    ok = solver <= precision * lower or upper == lower or precision != precision
    split = (f" = truncation {truncation:.3g} + solver {solver:.3g}" if truncation else "")
    return Check("precision", bool(ok), (
        f"width {upper - lower:.3g}{split}; solver's part "
        f"{'<=' if ok else '>'} {precision:g} x {lower:.7g}"))
