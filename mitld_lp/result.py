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
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from mitld_lp import report
from mitld_lp.checks import Check

if TYPE_CHECKING:
    from mitld_lp.automata.dta import DTA
    from mitld_lp.automata.sta import STA
    from mitld_lp.model import Model
    from mitld_lp.solvers.result import Status

__all__ = ["Result", "Part", "SynthesisResult", "from_models", "precision_check"]


@dataclass(frozen=True, slots=True, eq=False)
class Result:
    """What :func:`mitld_lp.synthesize` returns on every route (module docs).

    ``lower``: what the returned controller achieves in the real, untruncated world
    (for a band, whatever law of the band the events follow; with constraints, each
    constraint holding); ``upper``: what no policy beats; the optimum lies in between.
    Both hold in exact arithmetic for the model as written, its decimal probabilities
    (:mod:`mitld_lp.solvers.certify`).  For ``objective="min"`` ``upper`` is what the
    controller guarantees at most, ``lower`` what no policy goes below: solved as a
    minimum on the task's own automaton (``sense == "min"``: a co-safe task on the plain
    route), or read back from the complement's maximum (``Pmin(task) = 1 - Pmax(not
    task)``, :attr:`complemented`), ``complement`` then the complement's bracket.
    ``exact``: with ``exact=True`` the optimum as fractions, the bracket then their
    floats rounded outward.  ``value``: the method's
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
    part: Part  # the route's own part of the answer (its record, :class:`Part`)
    solve_cpu: float = float("nan")  # CPU seconds of the solve stage (all threads)
    dta: DTA | None = None  # the task's automaton (its complement if ``complemented``)
    # laws known within a band: each such event and its law's label
    bands: Mapping[str, str] = field(default_factory=dict)
    # the certificate's parts: for a minimum read back from the complement's maximum,
    # the complement's own bracket (1 - the task's probability lies in it, kept with its
    # digits where the task's bracket rounds to 1); the relative precision asked; the
    # bracket's width split into the truncation's part (the two models' optima apart)
    # and the solver's (the certificates' slack)
    complement: tuple[float, float] | None = None
    precision: float = float("nan")
    width: Mapping[str, float] = field(default_factory=dict)
    # exact=True: the optimum as fractions (mitld_lp.exact.ExactAnswer); lower and upper
    # are then its two fractions rounded outward
    exact: Any = None
    # how the solver optimised the solved automaton's target: "min" for a minimum solved
    # as one (the automaton is the task's own); "max" otherwise
    sense: str = "max"

    @property
    def complemented(self) -> bool:
        """Whether the solved automaton (``dta``, the controller's) is the task's
        complement, its values read back as ``1 -`` them: a minimum not solved as one."""
        return self.objective == "min" and self.sense == "max"

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
        return self.mdp if self.part.interval else None

    # the route's part, read through its record (one name per quantity, as before)
    @property
    def lower_model(self) -> Any:
        """The controller's solved model (the lower one; for a minimum solved as one the
        upper one): plain, robust and sensed routes."""
        return self.part.lower_model

    @property
    def upper_model(self) -> Any:
        """The bound's solved model: plain, robust and sensed routes."""
        return self.part.upper_model

    @property
    def acceptance(self) -> Any:
        """The target the bracket is about (its goal, its components)."""
        return self.part.acceptance

    @property
    def goal(self) -> np.ndarray | None:
        """Robust: the states that satisfy the task robustly."""
        return self.part.goal

    @property
    def constraints(self) -> tuple[Any, ...]:
        """With constraints: each one's ``ConstraintValue``."""
        return self.part.constraints

    @property
    def then(self) -> str | None:
        return self.part.then

    @property
    def secondary(self) -> float | None:
        return self.part.secondary

    @property
    def steps(self) -> float:
        """With constraints: the expected steps of the returned policy."""
        return self.part.steps

    @property
    def message(self) -> str:
        return self.part.message

    @property
    def merged(self) -> Any:
        """With constraints: the model the LP solved."""
        return self.part.merged

    @property
    def joint(self) -> Any:
        """With constraints: the joint automaton of the task and the constraints."""
        return self.part.joint

    @property
    def prob(self) -> np.ndarray | None:
        """With constraints: per merged choice, the policy's probability."""
        return self.part.prob

    @property
    def stay(self) -> np.ndarray | None:
        """With constraints: per merged state, the probability of staying."""
        return self.part.stay

    @property
    def sensors(self) -> Mapping[str, Any]:
        """Sensors that miss events: each sensed event's sensor."""
        return self.part.sensors

    @property
    def belief(self) -> Any:
        """Sensors that miss events: the information-state product's record."""
        return self.part.belief

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
        """The policy as data (the route's table: :meth:`Part.policy_table`)."""
        return self.part.policy_table(self)

    def write_policy(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> Path:
        """Write :meth:`policy_table` to ``path`` (:func:`mitld_lp.files.write.write_policy`)."""
        from mitld_lp.files.write import write_policy

        return write_policy(self, path, overwrite=overwrite)

    def summary(self) -> dict[str, Any]:
        """A JSON-ready record, the CLI's ``--json`` (:func:`mitld_lp.report.summary`)."""
        return report.summary(self)


class Part:
    """A route's own part of an answer, reached from :class:`Result` by ``part``: each
    route has its record, a subclass with its fields (the two solved models, the
    constraints' values and the randomised policy, the sensors and the information
    states).  A quantity a route does not have reads as the defaults here.  What a
    reader asks of an answer instead of its route's name: ``interval`` (the model is an
    interval MDP), ``randomised`` (the policy is ``prob`` / ``stay`` on the ``merged``
    model of the ``joint`` automaton), ``observation_based`` (the controller acts on
    what sensors report), ``kept_components`` (the policy keeps a safety part in the
    product's accepting end components), ``reading`` (a band read for the robot's
    ``"worst"`` law or its ``"best"``, ``Settings.bands``); and its policy table and
    JSON keys."""

    __slots__ = ()
    lower_model: Any = None
    upper_model: Any = None
    acceptance: Any = None
    goal: np.ndarray | None = None
    constraints: tuple[Any, ...] = ()
    then: str | None = None
    secondary: float | None = None
    steps: float = float("nan")
    message: str = ""
    merged: Any = None
    joint: Any = None
    prob: np.ndarray | None = None
    stay: np.ndarray | None = None
    sensors: Mapping[str, Any] = MappingProxyType({})
    belief: Any = None
    interval: bool = False
    randomised: bool = False
    observation_based: bool = False
    kept_components: bool = False
    reading: str = "worst"

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        """The policy as data, one row per state (:func:`mitld_lp.report.policy_table`)."""
        return report.model_table(result)

    def summary(self, result: Result) -> dict[str, Any]:
        """The JSON keys this route fills (:func:`mitld_lp.report.summary`)."""
        return report.models_summary(result)


#: The name of earlier releases, for code that imports it: the same class.
SynthesisResult = Result


def from_models(first: Any, second: Any, initial: int, objective: str,
                precision: float = float("nan"), *, truncated: bool = False,
                sense: str = "max", exact: Any = None) -> dict[str, Any]:
    """The answer's fields read from two solved models (plain and robust routes):
    ``first`` the controller's, ``second`` the bound's (for a maximum the lower and the
    upper truncation model, for a minimum solved as one, ``sense="min"``, the upper then
    the lower: :func:`mitld_lp.routes.plain.solve_models`; one object when nothing is
    truncated).  The bracket is the lower truncation model's certified lower bound and
    the upper one's certified upper bound (``bounds``: for a maximum the policy's value
    and the optimum, for a minimum the optimum and the policy's value), in the task's
    terms (a minimum solved as the complement's maximum is read back, rounded outward,
    with the complement's bracket kept); with an ``exact`` answer
    (:class:`mitld_lp.exact.ExactAnswer`) its fractions rounded outward.  The status is
    ``OPTIMAL`` when both solves succeeded, else the first other; every check once
    (otherwise each check's name says which model it checked), and the check that the
    solver's part of the width is within ``precision`` of the value (``truncated``: the
    two models differ by the truncation, whose part of the width is reported apart)."""
    from mitld_lp.solvers.certify import float_down, float_up, one_minus
    from mitld_lp.solvers.result import Status

    minimum = sense == "min"
    low_model, high_model = (second, first) if minimum else (first, second)
    low, high = float(low_model.bounds[0]), float(high_model.bounds[1])
    models = (first,) if second is first else (first, second)
    complement = None
    if objective == "min" and not minimum:
        complement = (low, high)
        (lower, upper), value = one_minus(low, high), 1.0 - first.value
    else:
        lower, upper, value = low, high, first.value
    if exact is not None:  # the fractions themselves, not their floats' differences
        lower, upper = float_down(exact.lower), float_up(exact.upper)
        if complement is not None:
            complement = (float_down(1 - exact.upper), float_up(1 - exact.lower))
    # the solver's part of the width: each model's own bracket (its certificate's two
    # bounds), held to the precision relative to that model's value in the task's terms;
    # the rest is the truncation's (the two models' optima apart)
    own = [(float(m.bounds[1]) - float(m.bounds[0]),
            1.0 - float(m.bounds[1]) if complement is not None else float(m.bounds[0]))
           for m in models]
    if exact is not None:  # both ends are the fractions: what is left is their rounding
        own = [(upper - lower - float(exact.upper - exact.lower), lower)]
    total = upper - lower
    solver = min(sum(w for w, _ in own), total)
    apart = max(total - solver, 0.0) if truncated else 0.0
    checks = [c if len(models) == 1 else Check(f"{m.which} model: {c.name}", c.passed, c.detail)
              for m in models for c in m.checks]
    checks.append(precision_check(lower, upper, solver, apart, precision, own=own))
    return {
        "lower": lower, "upper": upper, "value": float(value),
        "status": next((m.status for m in models if m.status is not Status.OPTIMAL),
                       Status.OPTIMAL),
        "certified": all(c.passed for c in checks),
        "checks": tuple(checks),
        "sense": sense,
        "complement": complement, "precision": precision,
        "width": {"total": total, "truncation": apart, "solver": solver},
    }


def precision_check(lower: float, upper: float, solver: float, truncation: float,
                    precision: float, *,
                    own: list[tuple[float, float]] | None = None) -> Check:
    """The check that the solver's part ``solver`` of the bracket's width is at most
    ``precision`` times the value (``lower``); the truncation's part is reported.
    ``own``: the solver's part as (width, value) per model, each held to ``precision``
    times its own value (a truncated minimum's lower model may be worth 0 where the
    upper one is not)."""
    parts = [(solver, lower)] if own is None else own
    ok = precision != precision or upper == lower or all(
        w <= precision * v or w <= 0.0 for w, v in parts)
    split = (f" = truncation {truncation:.3g} + solver {solver:.3g}" if truncation else "")
    said = " and ".join(f"{w:.3g} {'<=' if w <= precision * v or w <= 0.0 else '>'} "
                        f"{precision:g} x {v:.7g}" for w, v in parts)
    return Check("precision", bool(ok), f"width {upper - lower:.3g}{split}; solver's part "
                 + said)
