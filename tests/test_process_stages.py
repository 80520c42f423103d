"""The PRISM load's labels and names read without a sort, and the product's keys split by
shifts, against independent routes: Python's own counting and division, stormpy's model
read state by state and row by row, and Storm's answer on the product written as DRN."""

from __future__ import annotations

import importlib.util
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.product.states import KeyCodec
from mitld_lp.worlds.prism_labels import _small_unique, repeated

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")

# Two unlabelled commands, two commands of one action in a module (their choices named
# when first read), and labels that make several distinct sets over the states.
WALK = """mdp
module walker
  x : [0..4] init 0;
  y : [0..2] init 0;
  [go] x<4 -> 0.7 : (x'=x+1) + 0.3 : true;
  [go] x>0 -> 0.6 : (x'=x-1) + 0.4 : (y'=min(y+1,2));
  [] y<2 -> 0.5 : (y'=y+1) + 0.5 : (x'=max(x-1,0));
  [] y>0 -> (y'=y-1);
endmodule
label "east" = x>=3;
label "high" = y=2;
label "mid" = y=1;
label "odd" = mod(x,2)=1;
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "walk.prism"
    path.write_text(text)
    return path


def _many_labels(count: int) -> str:
    """WALK with ``count`` more labels, one per threshold of ``x + 3y``."""
    extra = "".join(f'label "t{k}" = x+3*y>={k % 11};\n' for k in range(count))
    return WALK + extra


# --------------------------------------------------------------------------- arrays


@pytest.mark.parametrize("width", [1, 2])
def test_small_unique_is_the_distinct_rows_in_order_and_each_rows_index(width: int) -> None:
    rng = np.random.default_rng(width)
    packed = (rng.integers(0, 3, size=(500, width)) << rng.integers(0, 7, size=(500, width))
              ).astype(np.uint8)
    rows, inverse = _small_unique(packed)
    # independent route: Python tuples, sorted (bytes compare as the big-endian number)
    expected = sorted({tuple(int(b) for b in r) for r in packed})
    assert [tuple(int(b) for b in r) for r in rows] == expected
    where = {r: i for i, r in enumerate(expected)}
    assert [where[tuple(int(b) for b in r)] for r in packed] == inverse.tolist()


def test_repeated_keys_are_those_counted_twice() -> None:
    rng = np.random.default_rng(7)
    # grouped by state, as the load's keys come: state * (labels + 1) + label + 1
    states = np.sort(rng.integers(0, 40, 400))
    keys = states * 6 + rng.integers(0, 6, 400)
    counted = Counter(keys.tolist())
    assert repeated(keys).tolist() == sorted(k for k, n in counted.items() if n > 1)
    assert repeated(np.arange(10)).size == 0


@pytest.mark.parametrize(("n_q", "n_sit"), [(3, 1), (4, 1), (1, 1), (4, 8), (3, 6), (5, 2)])
@pytest.mark.parametrize("dtype", [np.int32, np.int64])
def test_unkey_is_pythons_division(n_q: int, n_sit: int, dtype: type) -> None:
    codec = KeyCodec(n_q, n_sit)
    keys = np.random.default_rng(n_q * 10 + n_sit).integers(0, 2**30, 300).astype(dtype)
    g, q, sid = codec.unkey(keys)
    for k, a, b, c in zip(keys.tolist(), g.tolist(), q.tolist(), sid.tolist(), strict=True):
        assert (a, b, c) == (k // n_sit // n_q, k // n_sit % n_q, k % n_sit)
    assert g.dtype == q.dtype == sid.dtype == keys.dtype
    assert np.array_equal(codec.key(g, q, sid), keys)
    g[:] = -1  # new arrays: the keys are not changed through them
    assert (keys >= 0).all()


# --------------------------------------------------------------------------- the load


def _storm_model(path: Path) -> object:
    """Storm's own build of ``path`` with every label, its choice labels and its state
    valuations (the load's numbering: a whole build, no state limit, no terminal)."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_choice_labels()
    options.set_build_state_valuations()
    return stormpy.build_model(program, options=options)


@needs_storm
@pytest.mark.parametrize("extra", [0, 8, 20])  # 4, 12 and 24 labels: 1, 2 and 3 bytes
def test_state_labels_are_storms_state_by_state(tmp_path: Path, extra: int) -> None:
    from mitld_lp.worlds.prism import load_prism

    path = _write(tmp_path, _many_labels(extra))
    game = load_prism(path, explore="full")
    model = _storm_model(path)
    tables = game._tables
    assert len(tables.states) == model.nr_states
    chosen = game.proposition_names
    for s in range(model.nr_states):
        theirs = set(model.labeling.get_labels_of_state(s)) & chosen
        ours = tables.label_sets[int(tables.label_index[s])]
        assert ours == theirs, s
    assert len(set(tables.label_sets)) == len(tables.label_sets)  # each set once


@needs_storm
def test_transitions_are_storms_row_by_row(tmp_path: Path) -> None:
    from mitld_lp.worlds.prism import load_prism

    path = _write(tmp_path, WALK)
    tables = load_prism(path, explore="full")._tables
    model = _storm_model(path)
    matrix = model.transition_matrix
    groups = [matrix.get_row_group_start(s) for s in range(model.nr_states)]
    assert tables.choices.tolist() == [*groups, model.nr_choices]
    rows = []
    for c in range(model.nr_choices):
        rows.append(sorted((e.column, e.value) for e in matrix.get_row(c) if e.value != 0))
    ours = [sorted(zip(tables.targets[tables.branches[c]:tables.branches[c + 1]].tolist(),
                       tables.probabilities[tables.branches[c]:tables.branches[c + 1]].tolist(),
                       strict=True)) for c in range(model.nr_choices)]
    assert ours == rows


def _sound() -> object:
    """Storm's sound value iteration, 1e-9 absolute."""
    import stormpy
    import stormpy.environments

    env = stormpy.Environment()
    env.solver().force_soundness = True
    minmax = env.solver().min_max()
    minmax.method = stormpy.environments.MinMaxMethod.SOUND_VALUE_ITERATION
    minmax.precision = stormpy.Rational(1e-9)
    minmax.relative_termination_criterion = False
    return env


@needs_storm
@pytest.mark.parametrize("spec", ["!high U east", "F east", "G !(high & odd)"])
def test_the_answer_is_storms_on_the_exported_product(tmp_path: Path, spec: str) -> None:
    import stormpy

    from mitld_lp import Model, synthesize
    from mitld_lp.solvers import write_drn
    from mitld_lp.worlds.prism import load_prism

    path = _write(tmp_path, WALK)
    r = synthesize(Model.from_game(load_prism(path), spec))
    assert r.certified
    drn = write_drn(r.mdp, r.acceptance.goal, tmp_path / "p.drn", valuations=False)
    sense = getattr(r, "sense", "max")
    model = stormpy.build_model_from_drn(str(drn))
    prop = stormpy.parse_properties(f'P{sense}=? [F "target"]')[0]
    env = _sound()
    got = stormpy.model_checking(model, prop, environment=env)
    value = float(got.get_value_vector()[model.initial_states[0]])
    product_value = float(r.lower_model.value)
    assert abs(value - product_value) <= 1e-6
    # and Storm on the PRISM file itself: the task's value at the initial state
    program = stormpy.parse_prism_program(str(path))
    storm_text = {"!high U east": 'Pmax=? [!"high" U "east"]', "F east": 'Pmax=? [F "east"]',
                  "G !(high & odd)": 'Pmax=? [G !("high" & "odd")]'}[spec]
    props = stormpy.parse_properties(storm_text, program)
    built = stormpy.build_model(program, props)
    direct = stormpy.model_checking(built, props[0], environment=env)
    expected = float(direct.get_value_vector()[built.initial_states[0]])
    assert r.lower - 1e-7 <= expected <= r.upper + 1e-7
