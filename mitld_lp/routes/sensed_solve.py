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

A minimum is posed as the plain route poses it: a co-safe task minimised on its own
automaton (``Built.sense == "min"``), any other task as its complement's maximum read
back.  A task with a safety part (safety, obligation; a complement) is accepted by the
hypothesis runs that stay in persistent automaton states from some step on.  An
information state's hypotheses share its observations, so a run of information states
that settles in an end component keeps each hypothesis in the automaton states it shows
there: every hypothesis is accepted when each state of the component holds persistent
hypotheses only, and the target is the accepting end components of those states
(:func:`sensed_acceptance`), exact unless some end component keeps some hypotheses
persistent and others not.  Such *mixed* components (``(F(b & A) & G !h) | F c``: a
robot unsure whether it caught the bus waits for ever, one hypothesis kept safe, one
waiting for ``c``) are credited through a stop choice
(:mod:`mitld_lp.routes.sensed_mixed`): in the upper end each state with
the weight of its persistent hypotheses, in the lower each maximal one with those
persistent throughout it, the controller's value then found on its own chain; the check
``observation-based acceptance`` says ``bracketed``.  Where the task's open obligations
are bounded (``F[0,10] b1 & G !puddle``) no end component is mixed and the target is
exact.
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

__all__ = ["SensedPart", "Mixed", "sensed_acceptance", "solve_sensed"]

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


@dataclass(frozen=True, slots=True, eq=False)
class Mixed:
    """End components that keep some hypotheses persistent and not others
    (:mod:`mitld_lp.routes.sensed_mixed`): ``outer`` the accepting end components of the
    states with some persistent hypothesis, ``mixed`` their states outside the exact
    target, ``every`` the states whose every hypothesis is persistent, ``keep`` the
    persistent automaton states."""

    outer: Any
    mixed: np.ndarray
    every: np.ndarray
    keep: frozenset[int]


def sensed_acceptance(mdp: MDP, dta: DTA) -> tuple[Acceptance, Mixed | None, Check]:
    """The target of ``dta``'s task on its information-state product ``mdp`` (module
    docs): for a co-safe task the product's target; for a task with a safety part the
    accepting end components of the states whose every hypothesis is persistent, and
    the end components that mix persistent hypotheses with others (else None); with
    the check that says which."""
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
    outer = accepting_end_components(mdp, some) if (some & ~every).any() else inner
    mixed = outer.union & ~inner.union
    if not mixed.any():
        return (Acceptance(inner.union, inner), None,
                Check("observation-based acceptance", True,
                      "exact: no end component mixes persistent hypotheses with others"))
    log.info("sensed acceptance: %d information states lie in end components that keep "
             "some hypotheses persistent and not others (module docs)", int(mixed.sum()))
    return (Acceptance(inner.union, inner), Mixed(outer, mixed, every, keep),
            Check("observation-based acceptance", True,
                  f"bracketed: {int(mixed.sum())} information states in end components "
                  "that keep some hypotheses persistent and not others; lower: the "
                  "controller's value with each end component credited with its "
                  "hypotheses persistent throughout, upper: each state credited with its "
                  "persistent hypotheses"))


def _mixed_models(mdp: MDP, mixed: Mixed, low: ModelSolution, s: Any, t0: float,
                  eta: float, complement: bool) -> tuple[ModelSolution, ModelSolution]:
    """The two ends where end components are mixed (:mod:`mitld_lp.routes.sensed_mixed`):
    the controller's model (its value on its chain, if above ``low``'s, which counts
    those components lost) and the upper end's."""
    from mitld_lp.routes.sensed_mixed import (
        chain_value,
        component_credit,
        persistent_weight,
        real_policy,
        with_stops,
    )

    n, pad = mdp.n_states, np.zeros(2, dtype=bool)
    won = np.concatenate([np.asarray(mixed.outer.union & ~mixed.mixed), pad])
    upper = with_stops(mdp, {int(y): persistent_weight(mdp.states[y], mixed.keep)
                             for y in np.flatnonzero(mixed.mixed)})
    high = solve_models(upper, Acceptance(upper.target | won, None), s, t0, "max", eta,
                        complement=complement)[1]
    stopped = with_stops(mdp, component_credit(mdp, mixed.outer.mecs.mec_of, mixed.mixed,
                                               mixed.keep))
    kept = accepting_end_components(stopped, np.concatenate([mixed.every, [True, False]]))
    first = solve_models(stopped, Acceptance(kept.union, kept), s, t0, "max", eta,
                         complement=complement)[0]
    policy = real_policy(mdp, stopped, first.policy, mixed.outer.keep)
    chain = chain_value(mdp, policy, mixed.keep)
    value = solve_models(chain, Acceptance(np.asarray(chain.target, dtype=bool), None), s,
                         t0, "max", eta, complement=complement)[0]
    said = Check("controller's value on its chain", value.certified,
                 "its bottom components credited with the hypotheses persistent in each")
    candidate = replace(value, policy=policy, policy_values=value.policy_values[:n],
                        prob0=value.prob0[:n], checks=(*value.checks, said))
    return (candidate if candidate.bounds[0] >= low.bounds[0] else low), high


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
    inner, mixed, check = sensed_acceptance(mdp, dta)
    low, high = solve_models(mdp, inner, s, t2, built.sense, eta, complement=complement)
    if mixed is not None:  # both ends on their credited models (module docs)
        low, high = _mixed_models(mdp, mixed, low, s, t2, eta, complement)
    low = replace(low, checks=(*low.checks, check))
    t3 = time.perf_counter()
    result = Result(
        route=posed.route.name, model=model, objective=posed.problem.objective, method=s.method,
        epsilon=eps, sta=belief.sta, mdp=mdp, dta=dta,
        part=SensedPart(low, high, dict(belief.sensors), belief),
        controller=controller_of(model.game, belief, low.policy),
        timings={**built.timings, "solve": t3 - t2},
        **from_models(low, high, mdp.initial, posed.problem.objective, s.precision,
                      truncated=bool(mdp.truncated.any()) or mixed is not None,
                      sense=built.sense))
    log.info("sensed synthesis: %s, certified=%s",  # outward, as every surface prints it
             bracket_text(result.lower, result.upper), result.certified)
    return result
