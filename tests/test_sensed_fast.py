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


def test_state_records_unpacked_once_at_the_first_read(monkeypatch) -> None:
    """The states' arrays stay packed through ``len`` and the absorbing mask (what the
    solve and the controller read), are unpacked at the first record asked for and
    not again; the records equal those of the product pickled and read back."""
    import pickle

    from mitld_lp.sensing import moves

    model = CASES["two cameras"]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6)
    states = belief.mdp.states
    calls = []
    unpack = moves.PackedRuns.unpack
    monkeypatch.setattr(moves.PackedRuns, "unpack",
                        lambda self: calls.append(1) or unpack(self))
    n = len(states)
    kinds = states.absorbing()
    assert calls == [] and n == belief.mdp.n_states and kinds.any()
    records = [states[i] for i in range(n)]
    assert calls == [1]
    again = pickle.loads(pickle.dumps(states))
    assert [again[i] for i in range(n)] == records
    assert calls == [1, 1]  # the copy read back is packed again, unpacked at its read
    # an information state's posteriors sum to 1 (not the empty arrays of a bad unpack)
    live = [s for s, k in zip(records, kinds.tolist(), strict=True) if not k]
    assert live and all(abs(sum(s.weights) - 1.0) < 1e-12 for s in live)
