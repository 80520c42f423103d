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
waiting for ``c``) are counted lost in the lower end and credited, in the upper, with
the weight of their persistent hypotheses by a stop choice (:func:`_credited`): the
bracket says so in its check.  Where the task's open obligations are bounded
(``F[0,10] b1 & G !puddle``) no end component is mixed and the answer is exact.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.checks import Check
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.problem import Posed
from mitld_lp.product import Absorbing
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


def sensed_acceptance(mdp: MDP, dta: DTA
                      ) -> tuple[Acceptance, tuple[MDP, Acceptance] | None, Check]:
    """The target of ``dta``'s task on its information-state product ``mdp`` (module
    docs): for a co-safe task the product's target; for a task with a safety part the
    accepting end components of the states whose every hypothesis is persistent, and,
    when end components mix persistent hypotheses with others, the upper end's model
    and target (:func:`_credited`; else None); with the check that says which."""
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
    mixed = outer.union & ~inner.union
    if not mixed.any():
        return (Acceptance(inner.union, inner), None,
                Check("observation-based acceptance", True,
                      "exact: no end component mixes persistent hypotheses with others"))
    log.info("sensed acceptance: %d information states lie in end components that keep "
             "some hypotheses persistent and not others; the lower end counts them lost, "
             "the upper credits each its persistent hypotheses' weight", int(mixed.sum()))
    return (Acceptance(inner.union, inner), _credited(mdp, mixed, inner.union, keep),
            Check("observation-based acceptance", True,
                  f"bracketed: {int(mixed.sum())} information states in end components "
                  "that keep some hypotheses persistent and not others, lost in the lower "
                  "end, credited with their persistent hypotheses' weight in the upper"))


def _credited(mdp: MDP, mixed: np.ndarray, won: np.ndarray, keep: frozenset[int]
              ) -> tuple[MDP, Acceptance]:
    """The upper end's model when end components mix persistent hypotheses with others
    (module docs): ``mdp`` with two new absorbing states (won, lost) and, at each
    ``mixed`` state ``y``, one more choice (``stop``) to won with the weight of its
    persistent hypotheses and to lost with the rest; the target its own, the ``won``
    end components and the new won state.  A run that settles in an end component ``B``
    is accepted with at most the weight of the hypotheses persistent in all of ``B``,
    at most the credit of any state of ``B``: the best stopping problem with these
    credits bounds every policy's value (the Snell envelope dominates the limit)."""
    n = mdp.n_states
    groups = np.asarray(mdp.row_groups, dtype=np.int64)
    matrix = sp.csr_array(mdp.matrix)
    stop = len(mdp.action_names)
    rows: list[sp.csr_array] = []
    sizes = np.diff(groups)
    actions: list[np.ndarray] = []
    for y in range(n):
        rows.append(matrix[groups[y]:groups[y + 1]])
        actions.append(np.asarray(mdp.choice_actions[groups[y]:groups[y + 1]]))
        if mixed[y]:
            state = mdp.states[y]
            c = math.fsum(w for (_, q), w in zip(state.hypotheses, state.weights,
                                                  strict=True) if q in keep)
            rows.append(sp.csr_array(([c, 1.0 - c], ([0, 0], [n, n + 1])), shape=(1, n + 2)))
            actions.append(np.array([stop], dtype=np.int32))
            sizes[y] += 1
    for k in (n, n + 1):  # won, lost: absorbing
        rows.append(sp.csr_array(([1.0], ([0], [k])), shape=(1, n + 2)))
        actions.append(np.array([ABSORB], dtype=np.int32))
    rows = [r if r.shape[1] == n + 2 else sp.csr_array(r, shape=(r.shape[0], n + 2))
            for r in rows]
    pad = np.zeros(2, dtype=bool)
    target = np.concatenate([np.asarray(mdp.target, dtype=bool), [True, False]])
    credited = MDP(
        matrix=sp.csr_array(sp.vstack(rows, format="csr")),
        row_groups=np.concatenate([[0], np.cumsum(np.concatenate([sizes, [1, 1]]))]),
        choice_actions=np.concatenate(actions).astype(np.int32),
        action_names=(*mdp.action_names, "stop"), initial=mdp.initial, target=target,
        sink=np.concatenate([np.asarray(mdp.sink, dtype=bool), [False, True]]),
        truncated=np.concatenate([np.asarray(mdp.truncated, dtype=bool), pad]),
        states=(*mdp.states, Absorbing.TARGET, Absorbing.SINK))
    return credited, Acceptance(target | np.concatenate([won, pad]), None)


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
    if outer is not None:  # the upper end on the credited model (module docs)
        high = solve_models(*outer, s, t2, built.sense, eta, complement=complement)[1]
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
