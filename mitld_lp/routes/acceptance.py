"""What "the task is satisfied" means on a product MDP: the reachability target.

For a co-safe task it is the product's ``target`` state (the automaton accepted).  For a
safety or obligation task (the automaton has :data:`~mitld_lp.automata.dta.SAFE`
states) it is the union of the maximal end components of the product states whose
automaton state is persistent (:mod:`mitld_lp.solvers.accepting`): reaching it and then
playing its internal choices forever satisfies the task, and no policy does better.

One rule in one place: :func:`synthesize <mitld_lp.synthesis.synthesize>`, the exports
and the policy table all take the target from :func:`acceptance`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitld_lp.automata.dta import DTA, SAFE
from mitld_lp.mdp import MDP
from mitld_lp.product import ProductState, ProductStates
from mitld_lp.solvers.accepting import AcceptingComponents, accepting_end_components

__all__ = ["Acceptance", "acceptance", "persistent_states"]


@dataclass(frozen=True, slots=True, eq=False)
class Acceptance:
    """The reachability target of a task on its product.

    Attributes:
        goal: ``(n_states,)`` bool, the target of the lower model (truncation loses);
            the upper model's is ``goal | mdp.truncated``.
        components: the accepting end components (``None`` for a co-safe task, whose
            goal is ``mdp.target``).
    """

    goal: np.ndarray
    components: AcceptingComponents | None

    @property
    def keeps(self) -> bool:
        """Whether the task has a safety part (the run continues inside the goal)."""
        return self.components is not None


def persistent_states(mdp: MDP, dta: DTA) -> np.ndarray:
    """``(n_states,)`` bool: the product's target state and the ordinary states whose
    automaton state is persistent (:attr:`DTA.persistent`: safe or accepting)."""
    keep = np.zeros(dta.n_states + 1, dtype=bool)  # index -1: the absorbing states
    keep[sorted(dta.persistent)] = True
    states = mdp.states
    if isinstance(states, ProductStates):
        q = states.automaton_states()
    else:  # a hand-made product: read the records
        q = np.array([s.automaton if isinstance(s, ProductState) else -1 for s in states],
                     dtype=np.int64)
    return (keep[q] & (q >= 0)) | np.asarray(mdp.target, dtype=bool)


def acceptance(mdp: MDP, dta: DTA) -> Acceptance:
    """The target of ``dta``'s task on its product ``mdp`` (module docs)."""
    if SAFE not in dta.kinds:
        return Acceptance(np.asarray(mdp.target, dtype=bool), None)
    components = accepting_end_components(mdp, persistent_states(mdp, dta))
    return Acceptance(components.union, components)
