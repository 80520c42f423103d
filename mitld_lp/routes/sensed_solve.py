"""The ``sensed`` route: the optimum over the policies that act on observations only, on
the information-state product (:mod:`mitld_lp.sensing.belief`), certified as the plain
route's answer is.

The information-state MDP is an ordinary MDP with a reachability target, so the
existing solvers apply unchanged: one analysis of both truncation models, interval
iteration of both in one pass, the occupancy LP of each (method ``lp``), the policy's
exact value on its Markov chain.  ``lower`` is that exact value in the lower model
(truncated hypotheses lose): an observation-based policy achieves it in the real world;
``upper`` is interval iteration's sound upper bound on the upper model: no
observation-based policy does better.  The width is at most the truncation's epsilon
achieved, up to the solver's tolerance.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.checks import Check
from mitld_lp.mdp import MDP
from mitld_lp.problem import Posed
from mitld_lp.report import bracket_text
from mitld_lp.result import Part, Result, from_models
from mitld_lp.routes.acceptance import Acceptance
from mitld_lp.routes.plain import ModelSolution, solve_models
from mitld_lp.routes.stages import Built
from mitld_lp.sensing.belief import InfoState
from mitld_lp.sensing.observe import controller_of
from mitld_lp.solvers.accepting import accepting_end_components

__all__ = ["SensedPart", "sensed_acceptance", "solve_sensed"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, eq=False)
class SensedPart(Part):
    """The sensed route's part of the answer: the two solved models of the
    information-state product, each sensed event's sensor, and that product's record;
    the controller acts on what the sensors report."""

    lower_model: ModelSolution = field()  # required (Part's default is for the other routes)
    upper_model: ModelSolution = field()
    sensors: Mapping[str, Any] = field()
    belief: Any = field()
    observation_based = True

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        from mitld_lp.sensing.table import sensed_table

        return sensed_table(result)


def sensed_acceptance(mdp: MDP, dta: DTA) -> tuple[Acceptance, Acceptance | None, Check]:
    """The target of ``dta``'s task on its information-state product ``mdp`` (module
    docs): for a co-safe task the product's target; for a task with a safety part the
    accepting end components of the states whose every hypothesis is persistent, and,
    when they differ, those of the states with some persistent hypothesis (the upper
    end's target, else None); with the check that says which."""
    if SAFE not in dta.kinds:
        return (Acceptance(np.asarray(mdp.target, dtype=bool), None), None,
                Check("observation-based acceptance", True, "reaching the accepting state"))
    keep = dta.persistent
    every = np.asarray(mdp.target, dtype=bool).copy()
    some = every.copy()
    for i, state in enumerate(mdp.states):
        if isinstance(state, InfoState):
            held = [q in keep for _, q in state.hypotheses]
            every[i], some[i] = all(held), any(held)
    inner = accepting_end_components(mdp, every)
    if not (some & ~every).any():
        return (Acceptance(inner.union, inner), None,
                Check("observation-based acceptance", True,
                      "exact: every information state holds persistent hypotheses only "
                      "or none"))
    outer = accepting_end_components(mdp, some)
    mixed = int((outer.union & ~inner.union).sum())
    if mixed == 0:
        return (Acceptance(inner.union, inner), None,
                Check("observation-based acceptance", True,
                      "exact: no end component mixes persistent hypotheses with others"))
    log.info("sensed acceptance: %d information states lie in end components that keep "
             "some hypotheses persistent and not others; the bracket counts them lost "
             "(lower) and won (upper)", mixed)
    return (Acceptance(inner.union, inner), Acceptance(outer.union, outer),
            Check("observation-based acceptance", True,
                  f"bracketed: {mixed} information states in end components that keep "
                  "some hypotheses persistent and not others, lost in the lower end and "
                  "won in the upper"))


def solve_sensed(posed: Posed, built: Built) -> Result:
    """Solve a problem posed on the ``sensed`` route (module docs) on its built
    information-state product (:func:`mitld_lp.synthesis.solve`)."""
    model, s = posed.model, posed.settings
    assert built.belief is not None  # built by the sensed route's build
    eps = model.epsilon if s.epsilon is None else s.epsilon
    belief, dta = built.belief, built.dta
    t2 = time.perf_counter()
    mdp = belief.mdp
    # an ordinary MDP with a reachability target: solved and certified as the plain
    # route's product is (both truncation models, bounds checked in exact arithmetic)
    from mitld_lp.solvers.certify import model_eta

    eta = model_eta(belief.sta, history=True)
    complement = posed.minimise and built.sense == "max"
    inner, outer, check = sensed_acceptance(mdp, dta)
    low, high = solve_models(mdp, inner, s, t2, built.sense, eta, complement=complement)
    if outer is not None:  # the upper end from the wider target (module docs)
        high = solve_models(mdp, outer, s, t2, built.sense, eta, complement=complement)[1]
    low = replace(low, checks=(*low.checks, check))
    t3 = time.perf_counter()
    result = Result(
        route=posed.route.name, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=belief.sta, mdp=mdp, dta=dta,
        part=SensedPart(low, high, dict(belief.sensors), belief),
        controller=controller_of(model.game, belief, low.policy),
        timings={**built.timings, "solve": t3 - t2},
        **from_models(low, high, mdp.initial, posed.problem.objective, s.precision,
                      truncated=bool(mdp.truncated.any()) or outer is not None,
                      sense=built.sense))
    log.info("sensed synthesis: %s, certified=%s",  # outward, as every surface prints it
             bracket_text(result.lower, result.upper), result.certified)
    return result
