"""The sensed controller's moves, held from the build through the solve to the
controller: each level's choices kept as rows of the level, in int16 where the level
has fewer than 32,768 choices (not the product's row numbers in int32), a bound on
their bytes computed here from the rows' count; the moves still answer as the product
built one state at a time says (``test_sensing_build.reference``)."""

from __future__ import annotations

import numpy as np
import pytest
from test_sensing_build import CASES, assert_same, reference

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing.belief import belief_product


@pytest.mark.parametrize("case", ["one camera", "two cameras", "a safety part"])
def test_level_choices_are_narrow_and_answer_as_before(case: str) -> None:
    model = CASES[case]()
    belief = belief_product(model.game, to_dta(model.spec), model.distributions,
                            dict(model.sensors), model.epsilon, max_states=10**6,
                            late_reports=False, merge=False)
    moves = belief.moves
    ends = [*moves.bases[1:].tolist(), belief.mdp.n_choices]
    rows = held = 0
    for base, end, runs in zip(moves.bases.tolist(), ends, moves.levels, strict=True):
        assert end - base < 2**15  # these levels are small: int16 holds their rows
        for run in runs:
            choice = run[0]
            if choice.size:
                assert 0 <= int(choice.min()) and int(choice.max()) < end - base
            rows += choice.size
            held += choice.nbytes
    assert rows > 0
    assert held <= 2 * rows  # two bytes a row, where the product's numbers took four
    assert_same(belief, reference(model, belief))  # the same moves as one at a time
    np.testing.assert_array_equal(moves.bases, np.sort(moves.bases))
