"""The stages every route shares, up to the model a solver works on.

    task (its complement for "min", unless the plain route minimises a co-safe task on
    its own automaton; with constraints, the joint automaton of the task and each
    constraint's formula) --to_dta--> DTA --make_sta--> STA --product(game)--> MDP
    (an interval MDP when some law is known only within a band)

Which automaton a minimum builds: a task whose acceptance is reaching the accepting
state (co-safe: no :data:`~mitld_lp.automata.dta.SAFE` state) is minimised on the plain
route as a minimum, on its own automaton (``Built.sense == "min"``), so a rare
probability keeps its digits; a task with a safety part (accepting end components), and
every minimum on the robust and constrained routes, is the complement's maximum read
back (``Pmin(phi) = 1 - Pmax(not phi)``, ``Built.sense == "max"``).

:func:`build_posed` builds them for a posed problem (:mod:`mitld_lp.problem`), whatever
its route; :func:`mitld_lp.synthesis.solve` then hands the :class:`Built` record to
the route's solver and certificate.  Every budget is checked before the work that would
exceed it (:func:`build_product`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from mitld_lp import defaults
from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.automata.joint import Joint, joint_automaton
from mitld_lp.automata.sta import STA, make_sta
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import FirstOccurrence
from mitld_lp.distributions.literal import from_spec
from mitld_lp.logic import check
from mitld_lp.logic.constraints import Constraint, ConstraintError
from mitld_lp.logic.syntax import DistLiteral, Formula, atoms
from mitld_lp.mdp import MDP
from mitld_lp.model import Model
from mitld_lp.problem import Posed
from mitld_lp.product import product, robust_product
from mitld_lp.product.imdp import IntervalMDP
from mitld_lp.worlds.game import Game

__all__ = ["Built", "build_product", "build_posed", "build_task", "build_interval",
           "build_joint", "joint_sta", "reaching"]


@dataclass(frozen=True, slots=True, eq=False)
class Built:
    """What :func:`build_product` and :func:`build_posed` return: the automaton, the STA
    and the product, with the seconds each construction took (``automaton``,
    ``product``), and the sense in which the product's target is optimised (``"min"``
    only for a minimum solved on the task's own automaton; a minimum read back from
    its complement's maximum is ``"max"`` here)."""

    dta: DTA  # the automaton the product is built from (the joint one with constraints)
    sta: STA
    mdp: MDP | IntervalMDP  # an interval MDP when some law is known only within a band
    timings: Mapping[str, float]
    joint: Joint | None = None  # with constraints: the task's and each constraint's parts
    belief: Any = None  # sensors that miss events: the information-state product's record
    sense: str = "max"  # "max" or "min": how the solver optimises the product's target


def reaching(dta: DTA) -> bool:
    """Whether ``dta``'s acceptance is reaching its accepting state (no
    :data:`~mitld_lp.automata.dta.SAFE` state: a co-safe task), so that a minimum of
    it is a minimal reachability probability on its own product."""
    return SAFE not in dta.kinds


def build_product(
    game: Game[Any],
    formula: Formula,
    laws: Mapping[str, FirstOccurrence],
    *,
    epsilon: float = defaults.EPSILON,
    clock_reduction: bool = True,
    truncation: Mapping[str, int] | None = None,
    max_states: int = defaults.MAX_STATES,
    max_automaton_states: int = defaults.MAX_AUTOMATON_STATES,
    max_memory: int | None = None,
    progress: bool | None = None,
    objective: str = "max",
) -> Built:
    """The stages up to the MDP: ``to_dta(formula)`` (with ``objective="min"`` the
    automaton the minimum is solved on:
    the task's own if it is co-safe, :func:`reaching`, else its complement, module
    docs), ``make_sta`` with the events' ``laws`` and
    the truncation budget ``epsilon`` (or the fixed ``truncation`` points), then the
    reachable ``product`` with ``game``.  Budgets, each checked before the work that
    would exceed it: no state space built here has more than ``max_states`` states; the
    automaton, whose states cost thousands of times more than the product's, also no
    more than ``max_automaton_states`` (:mod:`mitld_lp.defaults`); the product needs at
    most ``max_memory`` bytes (default: half the machine's memory)."""
    if objective not in defaults.OBJECTIVES:
        raise ValueError(f"objective: must be 'max' or 'min', got {objective!r}")
    t0 = time.perf_counter()
    dta = to_dta(formula, max_states=min(max_states, max_automaton_states))
    direct = objective == "min" and reaching(dta)
    if objective == "min" and not direct:
        dta = dta.complement()
    sta = make_sta(dta, laws, epsilon, clock_reduction=clock_reduction, truncation=truncation)
    t1 = time.perf_counter()
    mdp = product(game, sta, max_states=max_states, max_memory=max_memory, progress=progress)
    t2 = time.perf_counter()
    return Built(dta, sta, mdp, {"automaton": t1 - t0, "product": t2 - t1},
                 sense="min" if direct else "max")


def build_posed(posed: Posed, *, progress: bool | None = None) -> Built:
    """The stages of a posed problem, as its route builds them (:meth:`Route.build
    <mitld_lp.routes.route.Route.build>`)."""
    return posed.route.build(posed, progress)


def build_task(posed: Posed, progress: bool | None = None) -> Built:
    """The plain route's stages: the task's automaton (for ``objective="min"`` its own
    when it is co-safe, else its complement, module docs), the STA with the problem's
    truncation settings, and the product with the world, under the problem's budgets."""
    model, s = posed.model, posed.settings
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    return build_product(
        model.game, model.spec, model.distributions, epsilon=_epsilon(posed),
        clock_reduction=s.clock_reduction, truncation=s.truncation_map,
        max_states=s.max_states, max_automaton_states=s.max_automaton_states,
        max_memory=s.max_memory, progress=progress,
        objective="min" if posed.minimise else "max")


def build_interval(posed: Posed, progress: bool | None = None) -> Built:
    """The robust route's stages: the task's automaton (its complement for
    ``objective="min"``: a minimum is the complement's maximum read back), the STA, and
    the interval MDP with the world (also when every law is a point)."""
    model, s = posed.model, posed.settings
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    t0 = time.perf_counter()
    dta = to_dta(model.spec, max_states=min(s.max_states, s.max_automaton_states))
    if posed.minimise:
        dta = dta.complement()
    sta = make_sta(dta, model.distributions, _epsilon(posed),
                   clock_reduction=s.clock_reduction, truncation=s.truncation_map)
    t1 = time.perf_counter()
    mdp = robust_product(model.game, sta, max_states=s.max_states, max_memory=s.max_memory,
                         progress=progress)
    return Built(dta, sta, mdp, {"automaton": t1 - t0, "product": time.perf_counter() - t1})


def build_joint(posed: Posed, progress: bool | None = None, *,
                make: Callable[..., MDP | IntervalMDP] = product) -> Built:
    """The constrained routes' stages: the joint automaton of the task and the
    constraints' formulas (:func:`joint_sta`), its STA, and ``make``'s product with the
    world (:func:`~mitld_lp.product.product`, or :func:`~mitld_lp.product.robust_product`
    for a band), under the problem's budgets."""
    s = posed.settings
    t0 = time.perf_counter()
    joint, sta = joint_sta(posed)
    t1 = time.perf_counter()
    mdp = make(posed.model.game, sta, max_states=s.max_states, max_memory=s.max_memory,
               progress=progress)
    return Built(joint.dta, sta, mdp,
                 {"automaton": t1 - t0, "product": time.perf_counter() - t1}, joint)


def _epsilon(posed: Posed) -> float:
    s = posed.settings
    return posed.model.epsilon if s.epsilon is None else s.epsilon


def joint_sta(posed: Posed) -> tuple[Joint, STA]:
    """The joint automaton of the task (its complement for ``objective="min"``) and the
    constraints' formulas, with the events' laws and the truncation settings."""
    model, s, cons = posed.model, posed.settings, posed.problem.constraints
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    laws = _laws(model, cons)
    formulas = [c.formula for c in cons if c.kind == "prob"]
    cap = min(s.max_states, s.max_automaton_states)
    task = to_dta(model.spec, max_states=cap)
    parts = [task.complement() if posed.minimise else task,
             *(to_dta(f, max_states=cap) for f in formulas if f is not None)]
    joint = joint_automaton(parts, max_states=cap)
    eps = model.epsilon if s.epsilon is None else s.epsilon
    sta = make_sta(joint.dta, laws, eps, clock_reduction=s.clock_reduction,
                   truncation=s.truncation_map)
    return joint, sta


def _laws(model: Model, constraints: tuple[Constraint, ...]) -> dict[str, FirstOccurrence]:
    """The model's laws and those of the constraints' new events (inline literals)."""
    laws = dict(model.distributions)
    task = dict(check(model.spec).events)
    for c in constraints:
        if c.formula is None:
            continue
        events = {e for e, _ in check(c.formula).events}
        unknown = sorted(atoms(c.formula) - set(model.game.proposition_names) - events
                         - set(laws))
        if unknown:
            raise ConstraintError(
                f"constraint {str(c)!r}: proposition {unknown[0]!r} is neither a proposition "
                f"of the world ({', '.join(sorted(model.game.proposition_names))}) nor an event")
        for event, mu in check(c.formula).events:
            if event in task:
                if task[event] != mu:
                    raise ConstraintError(
                        f"constraint {str(c)!r}: event {event!r} has D[{task[event]}] in the "
                        f"spec and D[{mu}] here; one law per event")
            elif event in laws:
                continue
            elif isinstance(mu, DistLiteral):
                laws[event] = from_spec(mu)
            else:
                raise ConstraintError(
                    f"constraint {str(c)!r}: event {event!r} is not an event of the spec; "
                    f"give it an inline law (D[geometric(0.3)] {event}), not D[{mu}]")
    return laws
