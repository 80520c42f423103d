"""The sensed route's controller reads each state's action name from the policy's
choice in one pass over the states (:func:`mitld_lp.sensing.observe.controller_of`);
these tests compare its names with the ones the MDP's choice records spell, read here
state by state from the action codes (``-1``: the absorbing loop)."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensing_build import CASES

from mitld_lp.automata.translate import to_dta
from mitld_lp.product import Absorbing
from mitld_lp.sensing.belief import belief_product
from mitld_lp.sensing.observe import controller_of


def _expected(mdp, policy: np.ndarray) -> list[str | None]:
    out: list[str | None] = []
    for i, c in enumerate(policy.tolist()):
        if c < 0 or isinstance(mdp.states[i], Absorbing):
            out.append(None)
            continue
        code = int(mdp.choice_actions[c])
        out.append("absorb" if code == -1 else mdp.action_names[code])
    return out


@pytest.mark.parametrize("case", ["two cameras", "a safety part"])
def test_controller_names_each_states_chosen_action(case: str) -> None:
    model = CASES[case]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6)
    mdp = belief.mdp
    groups = np.asarray(mdp.row_groups)
    rng = np.random.default_rng(7)
    # a random choice of each state's own, and some states with none chosen (-1)
    policy = groups[:-1] + (rng.random(mdp.n_states) * np.diff(groups)).astype(np.int64)
    policy[rng.random(mdp.n_states) < 0.2] = -1
    got = controller_of(model.game, belief, policy).tables().actions
    want = _expected(mdp, policy)
    assert list(got) == want
    # the case is not degenerate: several names and a None appear
    assert None in want and len({w for w in want if w is not None}) >= 2


def test_controller_of_no_kept_state_names_none() -> None:
    model = CASES["one camera"]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6)
    policy = np.full(belief.mdp.n_states, -1, np.int64)
    assert list(controller_of(model.game, belief, policy).tables().actions) == \
        [None] * belief.mdp.n_states
