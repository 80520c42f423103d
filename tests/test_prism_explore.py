"""The own PRISM explorer (mitld_lp.worlds.prism_explore) against Storm's build: the load
with ``MITLD_PRISM_BUILDER=own`` must give the tables ``MITLD_PRISM_BUILDER=storm``
gives (Storm's build is the independent route: the same states in the same order, the
same choices, rows bit for bit, labels and choice names), on the repository's model and
on small programs written here that exercise the semantics the explorer reimplements;
and where the explorer declines (outside its fragment, a refusal) Storm's build runs
and its words stand."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stormpy")
pytest.importorskip("numba")

from mitld_lp.logic.parser import parse  # noqa: E402
from mitld_lp.worlds import WorldError  # noqa: E402
from mitld_lp.worlds.prism import load_prism  # noqa: E402
from mitld_lp.worlds.prism_explore import BUILDER_ENV, chosen_builder  # noqa: E402
from mitld_lp.worlds.table import LATE  # noqa: E402


def names(tables) -> list[str]:
    """Each choice's name, however the tables name it (late or at once)."""
    ids = tables.action_index
    late = ids >= LATE
    out = [None] * ids.size
    for c in np.flatnonzero(~late & (ids >= 0)).tolist():
        out[c] = tables.action_names[int(ids[c])]
    if late.any():
        codes, known = tables.action_names.names_of(np.flatnonzero(late))
        for c, k in zip(np.flatnonzero(late).tolist(), codes.tolist(), strict=True):
            out[c] = known[k]
    return out


def both(monkeypatch, path, **kw):
    """The load's tables with Storm's build and with the own explorer."""
    monkeypatch.setenv(BUILDER_ENV, "storm")
    storm = load_prism(path, **kw)._tables
    monkeypatch.setenv(BUILDER_ENV, "own")
    own = load_prism(path, **kw)._tables
    return storm, own


def same(storm, own) -> None:
    assert own.variables == storm.variables
    assert own.initial == storm.initial
    assert list(own.states) == list(storm.states)
    for field in ("choices", "branches", "targets", "label_index"):
        assert np.array_equal(getattr(own, field), getattr(storm, field)), field
    assert own.probabilities.tobytes() == storm.probabilities.tobytes()  # bit for bit
    assert own.label_sets == storm.label_sets
    assert own.decided == storm.decided
    assert np.array_equal(own.action_index, storm.action_index)
    assert tuple(own.action_names) == tuple(storm.action_names)
    assert names(own) == names(storm)
    assert (own.normalised is None) == (storm.normalised is None)


def write(tmp_path, text: str, name: str = "m.prism"):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("open_at_start", [True, False])
def test_corridor(monkeypatch, open_at_start) -> None:
    storm, own = both(monkeypatch, "models/corridor.prism",
                      constants={"open_at_start": open_at_start})
    same(storm, own)


SYNC3 = """mdp
global g : [0..3] init 0;
formula near = x + y >= 2;
module a
  x : [0..2] init 0;
  [go] x < 2 -> 0.5 : (x'=x+1) + 0.5 : true;
  [go] x = 2 -> 1 : (x'=0);
  [] x > 0 -> 1 : (x'=x-1) & (g'=min(3, g+1));
endmodule
module b
  y : [0..2] init 0;
  f : bool init false;
  [go] y < 2 -> 0.25 : (y'=y+1) + 0.75 : (f'=!f);
  [stop] f -> 1 : (f'=false);
  [] near & !f -> 1 : (y'=0);
endmodule
module c
  z : [0..4] init 1;
  [go] true -> 1/3 : (z'=mod(z + 2, 5)) + 2/3 : (z'=max(0, z - 1));
  [stop] z >= 1 -> 0.1 : (z'=floor(z / 2)) + 0.9 : (z'=ceil(pow(z, 1) / 3));
  [tick] g < 3 -> (z > 2 ? 0.6 : 0.4) : (g'=g+1) + (z > 2 ? 0.4 : 0.6) : true;
endmodule
module c2 = c [z=w, go=go, tick=tock] endmodule
label "goal" = x = 2 & y = 2;
label "odd" = mod(z, 2) = 1;
"""


def test_synchronisation_interleaving_and_operators(tmp_path, monkeypatch) -> None:
    """Three modules on ``go`` (two commands of it in ``a``: a choice per combination),
    two on ``stop``, unlabelled commands interleaved, a global variable, Booleans, a
    formula, a renamed module, min/max/floor/ceil/pow/mod/ite and a rational."""
    storm, own = both(monkeypatch, write(tmp_path, SYNC3))
    assert len(storm.states) > 50
    same(storm, own)


def test_terminal_condition(tmp_path, monkeypatch) -> None:
    """States where the task is decided are not expanded, as Storm's terminal option."""
    storm, own = both(monkeypatch, write(tmp_path, SYNC3), task=parse("F goal"))
    assert storm.decided > 0
    same(storm, own)


DEADLOCK = """mdp
module m
  x : [0..3] init 0;
  [go] x < 2 -> 0.5 : (x'=x+1) + 0.5 : (x'=x+2);
endmodule
label "end" = x >= 2;
"""


def test_deadlock_self_loops(tmp_path, monkeypatch) -> None:
    storm, own = both(monkeypatch, write(tmp_path, DEADLOCK))
    assert "deadlock" in names(storm)
    same(storm, own)


@pytest.mark.parametrize(("old", "new", "words"), [
    ("x'=x+2", "x'=x+3", "outside its range"),  # an update out of the variable's range
    ("0.5 : (x'=x+2)", "0.4 : (x'=x+2)", "sum to"),  # beyond PRISM's tolerance
])
def test_refused_in_storms_words(tmp_path, monkeypatch, old, new, words) -> None:
    path = write(tmp_path, DEADLOCK.replace(old, new))
    errors = []
    for builder in ("storm", "own"):
        monkeypatch.setenv(BUILDER_ENV, builder)
        with pytest.raises(WorldError) as info:
            load_prism(path)
        errors.append(str(info.value))
    assert words in errors[0]
    assert errors[1] == errors[0]


def test_sum_within_prism_tolerance_normalised_alike(tmp_path, monkeypatch) -> None:
    """0.8 + 0.1 + 0.1 is not 1 in doubles: Storm's checks refuse it, the load builds
    again without them and normalises; the own explorer's rows go the same way."""
    path = write(tmp_path, DEADLOCK.replace(
        "0.5 : (x'=x+1) + 0.5 : (x'=x+2)", "0.8 : (x'=x+1) + 0.1 : (x'=x+2) + 0.1 : true"))
    storm, own = both(monkeypatch, path)
    same(storm, own)


def test_init_block_left_to_storm(tmp_path, monkeypatch) -> None:
    text = DEADLOCK.replace("x : [0..3] init 0;", "x : [0..3];") + "init x = 0 endinit\n"
    storm, own = both(monkeypatch, write(tmp_path, text))
    same(storm, own)  # the explorer declined: Storm's build both times


def test_builder_variable(monkeypatch) -> None:
    monkeypatch.setenv(BUILDER_ENV, "Own")
    assert chosen_builder() == "own"
    monkeypatch.setenv(BUILDER_ENV, "fast")
    with pytest.raises(ValueError, match="MITLD_PRISM_BUILDER='fast'"):
        chosen_builder()


def test_two_choices_of_one_name_left_to_storm(tmp_path, monkeypatch) -> None:
    """Two enabled commands of one action in a module: two choices named ``go`` in a
    state, which Storm's choice origins tell apart (``go@m_cmd1``): Storm builds it."""
    text = DEADLOCK.replace("[go] x < 2 -> 0.5 : (x'=x+1) + 0.5 : (x'=x+2);",
                            "[go] x < 2 -> (x'=x+1);\n  [go] x < 3 -> (x'=x+1);")
    storm, own = both(monkeypatch, write(tmp_path, text))
    assert any("@" in name for name in names(storm))
    same(storm, own)


def test_two_choices_of_one_name_told_apart_by_their_commands(tmp_path, monkeypatch) -> None:
    """With a command without an action the choices are named late: two ``go`` choices
    of one state are then ``go@m_cmd1`` and ``go@m_cmd2`` in both builds."""
    text = DEADLOCK.replace("[go] x < 2 -> 0.5 : (x'=x+1) + 0.5 : (x'=x+2);",
                            "[go] x < 2 -> (x'=x+1);\n  [go] x < 3 -> (x'=x+1);\n"
                            "  [] x = 3 -> (x'=0);")
    storm, own = both(monkeypatch, write(tmp_path, text))
    assert {"go@m_cmd1", "go@m_cmd2"} <= set(names(storm))
    assert type(own.action_names).__name__ == "KnownNames"  # the own explorer's
    same(storm, own)
