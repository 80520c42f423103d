"""The ``warm`` verb and the load's word on a cold explorer (mitld_lp.cli.warm,
mitld_lp.worlds.prism_explore.compile_kernels, prism_build.own_build)."""

from __future__ import annotations

import logging

import pytest

pytest.importorskip("stormpy")

import stormpy  # noqa: E402

from mitld_lp.cli import main  # noqa: E402
from mitld_lp.worlds import prism, prism_build, prism_explore  # noqa: E402
from mitld_lp.worlds.prism import load_prism  # noqa: E402


def test_warm_program_builds_its_six_states(tmp_path):
    # by hand: x in 0..2 and b both ways are reached (go flips b or counts x up; x=2
    # returns to x=0 keeping b), 6 states; the label "done" holds at x=2 & b only
    prism_explore.compile_kernels(stormpy)
    assert prism_explore.kernel_ready()
    path = tmp_path / "warm.prism"
    path.write_text(prism_explore.WARM_PROGRAM, encoding="ascii")
    program = stormpy.parse_prism_program(str(path))
    compiled = prism_explore.compile_program(program, None)
    built = prism_explore.explore_program(compiled, 100)
    assert not isinstance(built, str)
    assert built.values.dtype.itemsize == 1  # x in 0..2 and b in 0..1: a byte each
    assert len(built.choices) == 7 and built.targets.size == built.probabilities.size
    values = {tuple(int(v) for v in row) for row in built.values}
    names = list(compiled.names)
    assert len(values) == 6
    assert {(row[names.index("x")], row[names.index("b")]) for row in values} == {
        (x, b) for x in range(3) for b in (0, 1)}
    flags = prism_explore.label_values(
        built, [compiled.label_expr[compiled.labels.index("done")]])
    done = {tuple(int(v) for v in built.values[i]) for i in range(len(built.values))
            if flags[i, 0]}
    assert done == {r for r in values if r[names.index("x")] == 2 and r[names.index("b")] == 1}


def test_warm_says_what_it_did(monkeypatch, capsys):
    from mitld_lp.util import warm_kernels  # the solve's kernels: tests/test_warm_*.py

    monkeypatch.setattr(warm_kernels, "compile_all", lambda *a: (0, 43, 0.0))
    prism_explore.compile_kernels(stormpy)  # cached from here (compiled once if cold)
    assert main(["warm"]) == 0
    assert "compiled already" in capsys.readouterr().out
    monkeypatch.setattr(prism_explore, "kernel_ready", lambda: False)  # as if cold
    assert main(["warm"]) == 0
    said = capsys.readouterr()
    assert "compiled the own PRISM explorer's kernels" in said.out
    assert "compiling the own PRISM explorer" in said.err  # before the half minute
    assert main(["warm", "-q"]) == 0
    assert capsys.readouterr().err == ""  # -q: nothing on stderr


def test_cold_explorer_said_once_and_storm_builds(monkeypatch, caplog, tmp_path):
    path = tmp_path / "warm.prism"
    path.write_text(prism_explore.WARM_PROGRAM, encoding="ascii")
    monkeypatch.delenv(prism_explore.BUILDER_ENV, raising=False)
    monkeypatch.setattr(prism_explore, "kernel_ready", lambda: False)
    monkeypatch.setattr(prism_build, "_COLD_SAID", [])
    monkeypatch.setattr(prism_build, "OWN_FROM_STATES", 0)  # a program this small too
    called = []
    monkeypatch.setattr(prism_explore, "explore_tables",
                        lambda *a, **k: called.append(a) or (None, "not asked"))
    with caplog.at_level(logging.INFO, logger="mitld_lp.worlds.prism"):
        first = load_prism(path)
        load_prism(path)
    said = [r for r in caplog.records if "mitld-lp warm" in r.getMessage()]
    assert len(said) == 1  # once a process
    assert not called  # Storm built both
    assert len(first._tables.states) == 6


@pytest.mark.parametrize("floor, own", [(None, False), (0, True)])
def test_auto_leaves_a_small_program_to_storm(monkeypatch, tmp_path, floor, own):
    # WARM_PROGRAM has 3 x 2 = 6 valuations, under the default floor
    assert prism_build.OWN_FROM_STATES > 6
    path = tmp_path / "warm.prism"
    path.write_text(prism_explore.WARM_PROGRAM, encoding="ascii")
    monkeypatch.delenv(prism_explore.BUILDER_ENV, raising=False)
    monkeypatch.setattr(prism_explore, "kernel_ready", lambda: True)
    if floor is not None:
        monkeypatch.setattr(prism_build, "OWN_FROM_STATES", floor)
    called = []
    monkeypatch.setattr(prism_explore, "explore_tables",
                        lambda *a, **k: called.append(a) or (None, "not asked"))
    monkeypatch.setattr(prism, "own_load", lambda *a, **k: None)  # the stormpy route's rule
    assert len(load_prism(path)._tables.states) == 6
    assert bool(called) == own
