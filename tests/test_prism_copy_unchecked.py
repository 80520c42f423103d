"""A whole PRISM build without Storm's exploration checks (prism-copy): the world it
gives against Storm's own model (states, transitions, the label a property names, the
property's value), an update out of range still refused in Storm's words, a second
build of one program and a build with a limit still checked by Storm, and the world
budget still refusing a model too large before any row is read."""

from __future__ import annotations

import importlib.util
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
label "goal" = x=N;
label "hurt" = hit;
"""


def _marked(monkeypatch: pytest.MonkeyPatch, module: object, name: str, log: Path,
            mark: Callable[..., str]) -> None:
    """``module.name`` writing a line to ``log`` at each call, ``mark(*args, **kwargs)``
    (a file: the capped child writes it as well)."""
    real = getattr(module, name)

    def marking(*a, **k):  # noqa: ANN002, ANN003, ANN202
        with log.open("a") as fh:
            fh.write(mark(*a, **k) + "\n")
        return real(*a, **k)

    monkeypatch.setattr(module, name, marking)


def _recording(monkeypatch: pytest.MonkeyPatch, log: Path) -> None:
    """Each build's exploration checks (True/False) written to ``log``."""
    from mitld_lp.worlds import prism_build

    _marked(monkeypatch, prism_build, "builder_options", log, lambda *a, **k: str(k["checks"]))


def _pmax(t, goal: np.ndarray) -> float:  # noqa: ANN001
    """Pmax of reaching ``goal`` from the initial state by value iteration on the copy's
    arrays, a loop over choices in Python (not the library's solvers)."""
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


def test_the_unchecked_copy_is_storms_own_model(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    import stormpy

    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "walk.prism"
    path.write_text(WALK)
    log = tmp_path / "checks.txt"
    _recording(monkeypatch, log)
    game = load_prism(path)
    assert log.read_text().split() == ["False"]  # one build, without Storm's checks
    t = game._tables
    program = stormpy.parse_prism_program(str(path))
    prop = stormpy.parse_properties('Pmax=? [F "goal"]', program)[0]
    options = stormpy.BuilderOptions()  # Storm's own: checks on, no terminal states
    options.set_build_all_labels()
    options.set_exploration_checks(True)
    model = stormpy.build_model(program, options=options)
    assert len(t.states) == model.nr_states
    assert int(t.targets.size) == model.nr_transitions
    assert len(t.choices) - 1 == model.nr_states and int(t.choices[-1]) == model.nr_choices
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
    assert t.normalised is None and t.checked


def test_an_update_out_of_range_is_still_refused_in_storms_words(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from mitld_lp.worlds import WorldError
    from mitld_lp.worlds.prism import load_prism

    path = tmp_path / "over.prism"
    path.write_text(WALK.replace("(x'=x+2)", "(x'=x+3)"))  # x=4: x+3 = 7 > N
    log = tmp_path / "checks.txt"
    _recording(monkeypatch, log)
    with pytest.raises(WorldError, match=r"module walker, command 2 \(\[jump\].*'x' the "
                       r"value 7, outside its range \[0\.\.6\]"):
        load_prism(path)
    # the unchecked build refused on the copy, then Storm's checked (exact) build words it
    assert log.read_text().split() == ["False", "True"]


def test_a_second_build_of_one_program_and_a_limited_build_keep_the_checks(
    tmp_path: Path,
) -> None:
    import stormpy

    from mitld_lp.worlds.prism_build import unchecked_first

    path = tmp_path / "walk.prism"
    path.write_text(WALK)
    program = stormpy.parse_prism_program(str(path))
    assert unchecked_first(program, None)
    assert not unchecked_first(program, 100)  # a build with a limit: checked
    options = stormpy.BuilderOptions()
    options.set_add_out_of_bounds_state(True)
    stormpy.build_model(program, options=options)
    assert not unchecked_first(program, None)  # Storm would refuse its variable twice
    with pytest.raises(RuntimeError, match="already exists"):  # (why: Storm's own refusal)
        stormpy.build_model(program, options=options)


def test_the_budget_refuses_a_large_model_with_the_unchecked_build(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from mitld_lp.worlds import prism_tables
    from mitld_lp.worlds.prism import PrismTooLarge, load_prism

    log = tmp_path / "checks.txt"
    _recording(monkeypatch, log)
    reads = tmp_path / "reads.txt"
    _marked(monkeypatch, prism_tables, "checked_rows", reads, lambda *a, **k: "read")
    path = tmp_path / "plane.prism"
    path.write_text("mdp\nmodule m\n  x : [0..2999] init 0;\n  y : [0..2999] init 0;\n"
                    "  [a] x<2999 -> 0.5 : (x'=x+1) + 0.5 : (y'=min(y+1, 2999));\n"
                    "  [b] y<2999 -> (y'=y+1);\nendmodule\nlabel \"goal\" = x=2999;\n")
    with pytest.raises(PrismTooLarge, match=r"max_states = 2,000"):
        load_prism(path, max_states=2000)
    assert log.read_text().split() == ["False"]  # the capped child's build, unchecked
    assert not reads.exists()  # refused before any row was read
