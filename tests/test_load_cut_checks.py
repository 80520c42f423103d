"""The PRISM load's checks with fewer passes (load-cut): the export's offsets checked
rising by one comparison of neighbours (against a loop in Python), an inconsistent
export still refused by name, the robot-choice check looked for only where an event
takes choices (a world with events against Storm's own model, row by row; a state with
only an event's command still refused naming the state), and the lean table levels'
"no row repeats a state" against a loop over the rows."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.product.table_levels import _rows_distinct
from mitld_lp.worlds import WorldError
from mitld_lp.worlds import prism_tables as pt

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")


def _rising_loop(values: list[int]) -> bool:
    return all(a < b for a, b in zip(values, values[1:], strict=False))


def _fake(choices: list[int], branches: list[int]):
    """A stand-in for Storm's export: these offsets, every branch to state 0 at 1."""
    def export(model, where, origins=False, labels=None):
        targets = np.zeros(branches[-1], dtype=np.int64)
        probs = np.ones(branches[-1])
        return (np.array(choices, dtype=np.int64), np.array(branches, dtype=np.int64),
                targets, probs, None, None)
    return export


def test_offsets_are_taken_exactly_where_a_loop_says_they_rise(monkeypatch) -> None:
    rng = np.random.default_rng(11)
    cases = [[0, 1], [0, 0, 1], [0, 1, 1], [0, 2, 1]]
    for _ in range(200):
        steps = rng.integers(0, 3, size=int(rng.integers(1, 30)))  # 0: a repeat
        cases.append([0, *np.cumsum(steps).tolist()])
    for choices in cases:  # as many branches as choices, one each
        m = choices[-1]
        monkeypatch.setattr(pt, "_export", _fake(choices, list(range(m + 1))))
        if m > 0 and _rising_loop(choices):
            assert pt.transition_arrays(None, "w.prism")[0].tolist() == choices
        else:
            with pytest.raises(WorldError, match="inconsistent"):
                pt.transition_arrays(None, "w.prism")
    for branches in cases:  # one choice per state, as many as the branches' rows
        m = len(branches) - 1
        monkeypatch.setattr(pt, "_export", _fake(list(range(m + 1)), branches))
        if branches[-1] > 0 and _rising_loop(branches):
            assert pt.transition_arrays(None, "w.prism")[1].tolist() == branches
        else:
            with pytest.raises(WorldError, match="inconsistent"):
                pt.transition_arrays(None, "w.prism")


def test_an_export_with_an_empty_state_or_choice_is_refused(monkeypatch) -> None:
    fake = _fake

    good = ([0, 1, 2], [0, 1, 2])
    monkeypatch.setattr(pt, "_export", fake(*good))
    arrays = pt.transition_arrays(None, "w.prism")
    assert [a.tolist() for a in arrays[:2]] == [[0, 1, 2], [0, 1, 2]]
    for choices, branches in (([0, 1, 1, 2], [0, 1, 2]),    # a state without a choice
                              ([0, 1, 2], [0, 1, 1])):      # a choice without a branch
        monkeypatch.setattr(pt, "_export", fake(choices, branches))
        with pytest.raises(WorldError, match=r"w\.prism: Storm's UMB export is inconsistent"):
            pt.transition_arrays(None, "w.prism")


EVENTS = """mdp
module m
  x : [0..3] init 0;
  [go]   x<3 -> 0.5:(x'=x+1) + 0.5:(x'=x);
  [stay] x<2 -> true;
  [tick] x=1 -> (x'=3);
  [go]   x=3 -> true;
endmodule
label "top" = x=3;
"""


@needs_storm
def test_a_world_with_events_is_storms_model_row_by_row(tmp_path: Path) -> None:
    import stormpy

    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "events.prism"
    path.write_text(EVENTS)
    game = load_prism(path, events=["tick"])
    t = game._tables
    program = stormpy.parse_prism_program(str(path))
    options = stormpy.BuilderOptions()
    options.set_build_choice_labels()
    options.set_build_state_valuations()
    options.set_build_all_labels()
    model = stormpy.build_model(program, options=options)
    matrix = model.transition_matrix
    groups = [matrix.get_row_group_start(s) for s in range(model.nr_states)]
    groups.append(matrix.nr_rows)
    assert t.choices.tolist() == groups
    for c in range(matrix.nr_rows):  # each row: its successors and probabilities
        row = [(e.column, e.value) for e in matrix.get_row(c)]
        lo, hi = int(t.branches[c]), int(t.branches[c + 1])
        assert list(zip(t.targets[lo:hi].tolist(), t.probabilities[lo:hi].tolist(),
                        strict=True)) == row
        labels = model.choice_labeling.get_labels_of_choice(c)
        if "tick" in labels:  # the event's choice: not the robot's
            assert t.action_index[c] == -1
            state = int(np.searchsorted(t.choices, c, side="right")) - 1
            assert t.effects["tick"][state] == c
        else:
            assert t.action_names[int(t.action_index[c])] in labels | {"deadlock"}
    assert sum(int(k >= 0) for k in t.effects["tick"].tolist()) == 1  # x=1 alone


@needs_storm
def test_a_state_with_only_an_event_is_refused_by_name(tmp_path: Path) -> None:
    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "stuck.prism"
    path.write_text("mdp\nmodule m\n x : [0..2] init 0;\n [go] x=0 -> (x'=1);\n"
                    " [tick] x=1 -> (x'=2);\n [go] x=2 -> true;\nendmodule\n")
    with pytest.raises(WorldError, match=r"stuck\.prism: at state \[x=1\] only event "
                                         r"commands are enabled"):
        load_prism(path, events=["tick"])
    load_prism(path)  # without the event, tick is the robot's: every state has a choice


def _distinct_loop(targets: list[int], branches: list[int]) -> bool:
    """Every row strictly increasing (Storm's sparse rows are), by a loop over rows."""
    return all(_rising_loop(targets[a:b]) for a, b in zip(branches, branches[1:],
                                                            strict=False))


def test_rows_distinct_is_a_loop_over_the_rows() -> None:
    rng = np.random.default_rng(5)
    for _ in range(300):
        lengths = rng.integers(1, 4, size=int(rng.integers(1, 12)))
        branches = np.concatenate(([0], np.cumsum(lengths))).astype(np.int64)
        targets = rng.integers(0, 6, size=int(branches[-1])).astype(np.int64)
        if rng.random() < 0.5:  # mostly rising rows, as Storm's
            for a, b in zip(branches[:-1], branches[1:], strict=True):
                targets[a:b] = np.sort(targets[a:b])
        assert _rows_distinct(targets, branches) == _distinct_loop(targets.tolist(),
                                                                   branches.tolist())
