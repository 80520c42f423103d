"""The PRISM load through an archive whose decided-states label needs a pax header
(prism-copy): the world it gives against Storm's own model for the property (states,
transitions, the label the property names, the property's value), read without
:mod:`tarfile`, and the world budget still refusing a model too large before any row
is read."""

from __future__ import annotations

import importlib.util
import tarfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                reason="needs stormpy: pip install -e '.[prism]'")

WALK = """mdp
const int N = 6;
module walker
  x : [0..N] init 0;
  hit : bool init false;
  [step] x<N & !hit -> 0.5 : (x'=x+1) + 0.25 : (x'=max(x-1, 0)) + 0.25 : (hit'=true);
  [jump] x<N-1 & !hit -> 0.5 : (x'=x+2) + 0.5 : (hit'=true);
  [rest] x=N | hit -> true;
endmodule
label "goal" = (x=N & !hit) | (x=N & hit & x>=N-1 & x<=N+1 & N>=1 & N<=100 & x+x>=N);
label "hurt" = hit;
"""
"""A walk whose goal's expression (the label Storm names the decided states by) is too
long for a ustar header once encoded."""



@pytest.fixture(autouse=True)
def _storms_build(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests look into Storm's build (its options, its second build, its files):
    the load uses it, not the own explorer (tests/test_prism_explore.py compares them)."""
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")


def _marked(monkeypatch: pytest.MonkeyPatch, module: object, name: str, log: Path,
            mark: Callable[..., str]) -> None:
    """``module.name`` writing ``mark(*args, **kwargs)`` as a line of ``log`` at each call
    (a file: the capped child writes it as well)."""
    real = getattr(module, name)

    def marking(*a, **k):  # noqa: ANN002, ANN003, ANN202
        with log.open("a") as fh:
            fh.write(mark(*a, **k) + "\n")
        return real(*a, **k)

    monkeypatch.setattr(module, name, marking)


def _pmax(t, goal: np.ndarray) -> float:  # noqa: ANN001
    """Pmax of reaching ``goal`` from the initial state, value iteration over the copy's
    arrays in a Python loop (not the library's solvers)."""
    n = len(t.choices) - 1
    v = goal.astype(float)
    for _ in range(2000):
        new = v.copy()
        for s in range(n):
            if goal[s]:
                continue
            best = 0.0
            for c in range(int(t.choices[s]), int(t.choices[s + 1])):
                lo, hi = int(t.branches[c]), int(t.branches[c + 1])
                best = max(best, float(np.dot(t.probabilities[lo:hi], v[t.targets[lo:hi]])))
            new[s] = best
        if np.max(np.abs(new - v)) < 1e-15:
            break
        v = new
    return float(v[t.initial])


def test_a_pax_named_label_is_read_and_the_world_is_storms(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    import stormpy

    from mitld_lp.logic import parse
    from mitld_lp.worlds import prism_archive
    from mitld_lp.worlds.prism import load_prism

    def no_tarfile(*a, **k):  # noqa: ANN002, ANN003, ANN202
        raise AssertionError("the archive went to tarfile")

    monkeypatch.setattr(tarfile, "open", no_tarfile)
    log = tmp_path / "pax.txt"
    _marked(monkeypatch, prism_archive, "_pax", log, lambda records: "pax")
    path = tmp_path / "walk.prism"
    path.write_text(WALK)
    game = load_prism(path, task=parse("F goal"))
    assert "pax" in log.read_text().split()  # the premise: a pax header was read
    t = game._tables
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "goal"]', program)[0]
    options = stormpy.BuilderOptions([prop])  # Storm's own: goal states not expanded
    options.set_build_all_labels()
    model = stormpy.build_model(program, options=options)
    assert len(t.states) == model.nr_states
    assert int(t.targets.size) == model.nr_transitions
    assert int(t.choices[-1]) == model.nr_choices
    assert game.decided == len(list(model.labeling.get_states("goal")))
    for label in ("goal", "hurt"):
        ours = [s for s in range(len(t.states))
                if label in t.label_sets[int(t.label_index[s])]]
        assert ours == sorted(model.labeling.get_states(label))
    goal = np.array([("goal" in t.label_sets[int(k)]) for k in t.label_index])
    storm = stormpy.model_checking(model, prop).get_value(model.initial_states[0])
    assert _pmax(t, goal) == pytest.approx(storm, abs=1e-9)
    # by hand: jumping 0 -> 2 -> 4 -> 6 (each 1/2) is best, 1/8; stepping from 0 gives
    # V0 = V1/2 + V0/4 with V1 = 0.15625 (its jump to 3), below it
    assert storm == pytest.approx(0.125, abs=1e-9)


def test_the_budget_refuses_a_large_model_before_any_row_is_read(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from mitld_lp.logic import parse
    from mitld_lp.worlds import prism_tables
    from mitld_lp.worlds.prism import PrismTooLarge, load_prism

    reads = tmp_path / "reads.txt"
    _marked(monkeypatch, prism_tables, "checked_rows", reads, lambda *a, **k: "read")
    path = tmp_path / "plane.prism"
    path.write_text("mdp\nmodule m\n  x : [0..2999] init 0;\n  y : [0..2999] init 0;\n"
                    "  [a] x<2999 -> 0.5 : (x'=x+1) + 0.5 : (y'=min(y+1, 2999));\n"
                    "  [b] y<2999 -> (y'=y+1);\nendmodule\n"
                    "label \"goal\" = x=2999 & y>=0 & y<=2999 & x+y>=2999;\n")
    with pytest.raises(PrismTooLarge, match=r"max_states = 2,000"):
        load_prism(path, max_states=2000, task=parse("F goal"), explore="full")
    assert not reads.exists()  # refused before any row was read (here or in the child)
