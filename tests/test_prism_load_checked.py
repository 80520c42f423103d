"""The PRISM load's rows checked once (prism-load): ``checked_rows`` and
``normalise_rows`` against sums written out in Python, a loaded world's table against
Storm's own model (states, transitions, each row, a value), the product built from a
table whose rows were checked when read the same as from one checked again, and the
world budget still refusing a model too large before its rows are read."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.worlds.successors import (
    PROBABILITY_TOLERANCE,
    checked_rows,
    distribution_faults,
    normalise_rows,
)

needs_storm = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                 reason="needs stormpy: pip install -e '.[prism]'")



@pytest.fixture(autouse=True)
def _storms_build(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests look into Storm's build (its options, its second build, its files):
    the load uses it, not the own explorer (tests/test_prism_explore.py compares them)."""
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")


def _in_order(lengths: list[int], probs: list[float]) -> tuple[list[int], list[float]]:
    """The faulty rows and each row's total, summed left to right in plain Python."""
    bad, totals, at = [], [], 0
    for r, k in enumerate(lengths):
        row = probs[at:at + k]
        at += k
        total = 0.0
        wrong = False
        for p in row:
            if not math.isfinite(p) or p < 0.0:
                wrong = True
            else:
                total += p
        totals.append(total)
        if k == 0 or wrong or abs(total - 1.0) > 1e-5:
            bad.append(r)
    return bad, totals


def test_checked_rows_are_the_rows_summed_in_order() -> None:
    rng = np.random.default_rng(3)
    lengths = rng.integers(0, 7, size=300)
    probs = rng.random(int(lengths.sum()))
    at = np.concatenate(([0], np.cumsum(lengths)))
    for r in range(0, 300, 3):  # a third of the rows made distributions
        probs[at[r]:at[r + 1]] /= probs[at[r]:at[r + 1]].sum()
    probs[at[7]] = np.nan if lengths[7] else 0.0
    probs[at[10]] = -0.25 if lengths[10] else 0.0
    bad, total, row = checked_rows(lengths, probs, 1e-5)
    want_bad, want_total = _in_order(lengths.tolist(), probs.tolist())
    assert bad.tolist() == want_bad
    assert total.tolist() == want_total  # the same sums, bit for bit
    assert row.tolist() == [r for r, k in enumerate(lengths.tolist()) for _ in range(k)]
    assert np.array_equal(distribution_faults(lengths, probs, 1e-5), bad)


def test_normalise_rows_given_the_totals_is_the_same_and_sums_to_one() -> None:
    lengths = np.array([3, 2, 1, 4])
    probs = np.array([0.8, 0.1, 0.1 + 4e-6, 0.5, 0.5, 1.0, 0.25, 0.25, 0.25, 0.25 - 3e-7])
    bad, total, row = checked_rows(lengths, probs, 1e-5)
    assert bad.size == 0
    alone = normalise_rows(lengths, probs)
    given = normalise_rows(lengths, probs, (total, row))
    assert given[1:] == alone[1:] and given[1] == 2  # rows 0 and 3 divided
    assert np.array_equal(given[0], alone[0])
    assert given[2] == pytest.approx(4e-6)
    for r in (0, 3):  # the divided rows: each probability over the row's sum
        a, z = int(lengths[:r].sum()), int(lengths[: r + 1].sum())
        assert given[0][a:z].tolist() == [p / float(total[r]) for p in probs[a:z].tolist()]
        assert abs(sum(given[0][a:z].tolist()) - 1.0) <= PROBABILITY_TOLERANCE
    assert distribution_faults(lengths, given[0]).size == 0


# A small MDP: two choices in s=0, a loop back, a sum PRISM accepts (0.3 + 0.3 + 0.4
# + 1e-7) that the game's tolerance does not, and a target.
SMALL = """mdp
module m
  s : [0..4] init 0;
  [a] s=0 -> 0.5 : (s'=1) + 0.5 : (s'=2);
  [b] s=0 -> 0.3 : (s'=3) + 0.3 : (s'=1) + 0.4000001 : (s'=0);
  [a] s=1 -> 0.9 : (s'=4) + 0.1 : (s'=0);
  [a] s=2 -> 0.2 : (s'=4) + 0.8 : (s'=3);
  [a] s=3 -> true;
  [a] s=4 -> true;
endmodule
label "goal" = s=4;
"""


def _storm_rows(path: Path) -> tuple[int, int, dict[int, list[dict[int, float]]], float]:
    """Storm's own build of the file: states, transitions, each state's rows (as
    successor -> probability, Storm's numbers) and its Pmax of reaching goal."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "goal"]', program)[0]
    model = stormpy.build_model(program, [prop])
    matrix = model.transition_matrix
    rows = {}
    for s in range(model.nr_states):
        lo, hi = matrix.get_row_group_start(s), matrix.get_row_group_end(s)
        rows[s] = sorted(({e.column: e.value for e in matrix.get_row(r)}
                          for r in range(lo, hi)), key=lambda d: sorted(d.items()))
    value = stormpy.model_checking(model, prop).get_value(model.initial_states[0])
    return model.nr_states, model.nr_transitions, rows, float(value)


def _loaded(tmp_path: Path, name: str, text: str) -> tuple[Path, object]:
    """The PRISM file ``text`` written as ``name`` and loaded as a world."""
    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / name
    path.write_text(text)
    return path, load_prism(path)


@needs_storm
def test_a_loaded_table_is_storms_model_its_rows_checked(tmp_path: Path) -> None:
    from mitld_lp.worlds.table import table_of

    path, game = _loaded(tmp_path, "small.prism", SMALL)
    t = game._tables
    assert t.checked and game.normalised is not None and game.normalised.rows == 1
    n, transitions, rows, _ = _storm_rows(path)
    assert (len(t.states), int(t.targets.size)) == (n, transitions) == (5, 11)  # 5 + 2 + 2 + 1 + 1
    for s in range(n):  # Storm numbers the states alike (breadth first from s=0)
        got = []
        for c in range(int(t.choices[s]), int(t.choices[s + 1])):
            lo, hi = int(t.branches[c]), int(t.branches[c + 1])
            got.append(dict(zip(t.targets[lo:hi].tolist(), t.probabilities[lo:hi].tolist(),
                                strict=True)))
        got.sort(key=lambda d: sorted(d.items()))
        assert len(got) == len(rows[s])
        for ours, storms in zip(got, rows[s], strict=True):
            total = math.fsum(storms.values())  # 1 but for the row PRISM accepts
            assert ours.keys() == storms.keys()
            for k, p in storms.items():
                assert ours[k] == pytest.approx(p / total, rel=1e-15)
    table = table_of(game)
    assert table is not None and table.checked
    lengths = np.diff(table.branches)
    assert distribution_faults(lengths, table.probabilities).size == 0  # what it says


@needs_storm
def test_the_product_of_a_checked_table_is_the_product_checked_again(tmp_path: Path) -> None:
    import dataclasses

    from mitld_lp import load_model, synthesize
    from mitld_lp.automata.sta import make_sta
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.model import Model
    from mitld_lp.product import product
    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "small.prism"
    path.write_text(SMALL)
    game = load_prism(path)
    m = Model.from_game(game, "F goal")
    sta = make_sta(to_dta(m.spec), m.distributions, m.epsilon)
    once = product(game, sta)

    class Again:  # the same table, declared unchecked: the product checks every row
        def __init__(self, inner):
            self.inner = inner

        def __getattr__(self, name):
            return getattr(self.inner, name)

        def as_table(self):
            return dataclasses.replace(self.inner.as_table(), checked=False)

    again = product(Again(game), sta)
    assert once.n_states == again.n_states and np.array_equal(once.row_groups, again.row_groups)
    assert (once.matrix != again.matrix).nnz == 0
    assert np.array_equal(once.matrix.data, again.matrix.data)
    # and the answer is Storm's
    model_path = tmp_path / "m.toml"
    model_path.write_text(f'spec = "F goal"\n[prism]\nfile = "{path}"\n')
    r = synthesize(load_model(model_path))
    _, _, _, value = _storm_rows(path)
    assert r.lower <= value * (1 + 1e-6) + 1e-9 and value <= r.upper * (1 + 1e-6) + 1e-9


@needs_storm
def test_the_world_budget_refuses_a_large_model_before_its_rows_are_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from mitld_lp.worlds import prism_tables
    from mitld_lp.worlds.prism import PrismTooLarge, load_prism

    marks = tmp_path / "read.txt"  # a file: the capped child writes it as well
    real = prism_tables.checked_rows

    def marked(*a, **k):
        with marks.open("a") as fh:
            fh.write("read\n")
        return real(*a, **k)

    monkeypatch.setattr(prism_tables, "checked_rows", marked)
    path = tmp_path / "huge.prism"
    path.write_text("mdp\nmodule m\n  x : [0..1999] init 0;\n  y : [0..1999] init 0;\n"
                    "  [a] x<1999 -> (x'=x+1);\n  [b] y<1999 -> (y'=y+1);\n"
                    "endmodule\nlabel \"goal\" = x=1999 & y=1999;\n")
    with pytest.raises(PrismTooLarge, match="max_states = 1,000"):
        load_prism(path, max_states=1000)
    assert not marks.exists()  # refused before any row was read (here or in the child)
    small = tmp_path / "small.prism"
    small.write_text(SMALL)
    assert load_prism(small).n_states == 5
    assert marks.read_text() == "read\n"  # the same route reads a model that fits


# Globals, Booleans, a renamed module, initial values from constants, a
# variable no command changes (Storm makes it a constant), names out of their order.
HEADS = """mdp
const int K = 2;
global zeta : [0..5] init K + 1;
global flag : bool init true;
module alpha
  m : [0..3] init K;
  b : bool init false;
  idle : [0..9] init 4;
  [go] m<3 -> 0.5 : (m'=m+1) & (b'=!b) + 0.5 : (zeta'=min(zeta+1,5));
  [stop] m=3 -> (flag'=false) & (m'=0);
endmodule
module beta = alpha [m=n, b=c, idle=idle2, go=go2, stop=stop2] endmodule
label "goal" = m=3 & n=3;
"""


def _with_init_block() -> str:
    """HEADS with an ``init`` block in place of the variables' initial values."""
    import re

    block = "init zeta=1 & flag & m=0 & n=1 & !b & !c & idle=4 & idle2=4 endinit\n"
    return re.sub(r" init [^;]+;", ";", HEADS).replace('label "goal"', block + 'label "goal"')


@needs_storm
def test_the_head_read_from_the_program_is_storms_build_of_one_state(tmp_path: Path) -> None:
    import stormpy

    from mitld_lp.worlds.prism_valuations import head, program_head

    path = tmp_path / "heads.prism"
    path.write_text(HEADS)
    plain = stormpy.parse_prism_program(str(path)).substitute_constants()
    variables, initial, known, booleans = head(stormpy, plain, "", False, str(path))
    assert program_head(plain) == (variables, known, booleans)
    assert initial == 0
    # by hand: sorted names; idle and idle2 are constants in Storm's program
    assert variables == ("b", "c", "flag", "m", "n", "zeta")
    assert known == (False, False, True, 2, 2, 3) and booleans == (0, 1, 2)
    other = tmp_path / "init.prism"
    other.write_text(_with_init_block())
    assert program_head(stormpy.parse_prism_program(str(other)).substitute_constants()) is None


@needs_storm
@pytest.mark.parametrize("name", ["heads.prism", "init.prism"])
def test_the_states_named_later_are_storms_valuations(tmp_path: Path, name: str) -> None:
    import json

    import stormpy

    from mitld_lp.worlds.prism import load_prism
    from mitld_lp.worlds.prism_valuations import DeferredValuations

    text = HEADS if name == "heads.prism" else _with_init_block()
    path = tmp_path / name
    path.write_text(text)
    game = load_prism(path)
    states = game._tables.states
    assert isinstance(states, DeferredValuations) and not states.built
    program = stormpy.parse_prism_program(str(path))
    options = stormpy.BuilderOptions()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    names = game.variables
    want = []
    for s in range(model.nr_states):  # Storm's own valuations, one state at a time
        values = json.loads(str(model.state_valuations.to_json(s)))
        want.append(tuple(values[v] for v in names))
    assert len(states) == model.nr_states
    assert game.initial == want[model.initial_states[0]]
    assert list(states) == want and states.built


# 3 x 50 states (more than a 64-bit word of a bit vector, not a whole number of bytes
# past it), labels true on scattered states.
WIDE_LABELS = """mdp
module m
  x : [0..49] init 0;
  y : [0..2] init 0;
  [go] x<49 -> 0.5 : (x'=x+1) + 0.5 : (y'=mod(y+1,3));
  [back] x>0 -> (x'=x-1);
endmodule
label "odd" = mod(x, 2) = 1;
label "corner" = x=49 & y=2;
label "never" = x>60;
label "thirds" = mod(x + y, 3) = 0;
"""


@needs_storm
def test_state_labels_read_from_the_export_are_storms_bit_vectors(tmp_path: Path) -> None:
    import stormpy

    from mitld_lp.worlds.prism_labels import agrees, indices
    from mitld_lp.worlds.prism_tables import label_states, read_export_parts

    path = tmp_path / "wide.prism"
    path.write_text(WIDE_LABELS)
    program = stormpy.parse_prism_program(str(path))
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    model = stormpy.build_model(program, options=options)
    assert model.nr_states == 150
    archive: dict[str, np.ndarray] = {}
    read_export_parts(model, str(path), labels=archive)
    assert {"odd", "corner", "never", "thirds"} <= set(archive)
    for label in ("odd", "corner", "never", "thirds", "deadlock"):
        want = np.fromiter(model.labeling.get_states(label), dtype=np.int64)  # one by one
        assert np.array_equal(label_states(model, label, archive), want)
        assert np.array_equal(indices(model.labeling.get_states(label)), want)
    # a bit order read wrong (each byte reversed) keeps the count, and is caught
    odd = archive["odd"]
    wrong = odd.copy()  # the whole bytes' bits reversed
    wrong[:144] = odd[:144].reshape(-1, 8)[:, ::-1].reshape(-1)
    assert int(wrong.sum()) == int(odd.sum()) and not np.array_equal(wrong, odd)
    assert agrees(odd, model.labeling.get_states("odd"))
    assert not agrees(wrong, model.labeling.get_states("odd"))
    assert np.array_equal(label_states(model, "odd", {"odd": wrong}),
                          np.flatnonzero(odd))  # Storm's bit vector then, not the flags


@needs_storm
def test_a_worlds_labels_are_storms(tmp_path: Path) -> None:
    import stormpy

    path, game = _loaded(tmp_path, "wide.prism", WIDE_LABELS)
    t = game._tables
    model = stormpy.build_model(stormpy.parse_prism_program(str(path)))
    assert len(t.states) == model.nr_states
    for label in ("odd", "corner", "never", "thirds"):
        want = set(np.fromiter(model.labeling.get_states(label), dtype=np.int64).tolist())
        got = {s for s in range(len(t.states)) if label in t.label_sets[t.label_index[s]]}
        assert got == want, label
