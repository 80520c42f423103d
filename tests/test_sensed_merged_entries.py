"""A choice's entries into one information state made one
(:func:`mitld_lp.sensing.rows.merged_entries`): with false alarms several observations
lead to one state, and the build without the merge (``rows.MERGE_ENTRIES`` off) keeps an
entry per observation.  Both builds are compared here: the same states, choices, moves
and posteriors; each merged row is the unmerged row with its entries into one state
added up by hand, left to right in the row's order, each at its first entry's place
(the same floats to the bit); and the certified brackets of both hold the exact optimum
over every per-step report history (tests/test_sensing_tasks.py's expectimax, in
fractions) and agree."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from test_false_alarms import HORIZON, LAW, MASSES, TASKS
from test_sensing_build import canonical
from test_sensing_tasks import expectimax_every_step

from mitld_lp import Model, synthesize
from mitld_lp.automata.translate import to_dta
from mitld_lp.distributions import pmf
from mitld_lp.sensing import rows
from mitld_lp.sensing.belief import belief_product

SENSORS = [(0.5, 0.2, 0), (0.8, 0.1, 1), (0.6, 0.3, 2)]  # detect, false_alarm, delay


def _model(task: str, detect: float, false_alarm: float, delay: int) -> Model:
    """test_false_alarms.py's task with a sensor on ``b`` that has false alarms."""
    world, spec, own_law, _ = TASKS[task]
    return Model.from_game(world, spec, events={"b": pmf(list(LAW))} if own_law else None,
                           sensors={"b": {"detect": detect, "false_alarm": false_alarm,
                                          "delay": delay}})


def _both(monkeypatch: pytest.MonkeyPatch, make, *args):
    """``make(*args)`` with the merge off, then on."""
    out = []
    for merge in (False, True):
        monkeypatch.setattr(rows, "MERGE_ENTRIES", merge)
        out.append(make(*args))
    return out


def _build(model):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6)


def _rows(matrix) -> list[list[tuple[int, float]]]:
    m = matrix.tocsr()
    return [list(zip(m.indices[a:b].tolist(), m.data[a:b].tolist(), strict=True))
            for a, b in zip(m.indptr[:-1].tolist(), m.indptr[1:].tolist(), strict=True)]


@pytest.mark.parametrize("task", sorted(TASKS))
@pytest.mark.parametrize("detect, false_alarm, delay", SENSORS)
def test_merged_rows_are_the_unmerged_rows_summed(monkeypatch, task: str, detect: float,
                                                  false_alarm: float, delay: int) -> None:
    plain, merged = _both(monkeypatch, _build, _model(task, detect, false_alarm, delay))
    a, b = plain.mdp, merged.mdp
    assert a.n_states == b.n_states and a.n_choices == b.n_choices
    assert np.array_equal(a.row_groups, b.row_groups)
    assert np.array_equal(a.choice_actions, b.choice_actions)
    want, got = canonical(plain), canonical(merged)
    for part in ("order", "initial", "weights", "moves"):
        assert got[part] == want[part], part
    repeated = 0
    for before, after in zip(_rows(a.matrix), _rows(b.matrix), strict=True):
        summed: dict[int, float] = {}
        for j, p in before:  # by hand: each state's entries added in the row's order
            summed[j] = summed[j] + p if j in summed else p
        repeated += len(before) - len(summed)
        assert after == list(summed.items())  # first places kept, the same bits
    assert repeated > 0  # the case has entries to merge (false alarms' report counts)
    assert b.matrix.nnz == a.matrix.nnz - repeated


@pytest.mark.parametrize("task", ["co-safe", "obligation"])
@pytest.mark.parametrize("objective", ["max", "min"])
def test_merged_and_unmerged_answers_hold_the_expectimax(monkeypatch, task: str,
                                                         objective: str) -> None:
    detect, false_alarm, delay = SENSORS[0]
    world, _, _, judge = TASKS[task]
    exact = expectimax_every_step(world, MASSES, Fraction(str(detect)), judge, HORIZON,
                                  false_alarm=Fraction(str(false_alarm)), delay=delay,
                                  sense=max if objective == "max" else min)
    model = _model(task, detect, false_alarm, delay)
    results = _both(monkeypatch, lambda: synthesize(model, objective=objective))
    for r in results:
        assert r.route == "sensed" and r.certified
        assert Fraction(r.lower) <= exact <= Fraction(r.upper), (r.lower, r.upper)
    plain, merged = results
    assert merged.mdp.n_transitions < plain.mdp.n_transitions
    assert merged.lower == pytest.approx(plain.lower, abs=1e-12)
    assert merged.upper == pytest.approx(plain.upper, abs=1e-12)
