"""A PRISM world's unlabelled commands' choices named when first read
(:mod:`mitld_lp.worlds.prism_names`, :mod:`mitld_lp.product.late_names`): the names are
those of Storm's own choice origins, read here from Storm's build of the file with them
(each choice's command set: its action, else its one command's ``<module>_cmd<k>``,
none: the deadlock self-loop); a policy, a controller and a DRN export after such a
load are those of the load that names every choice at once (Storm's choice origins in
the first build)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.worlds.prism import load_prism

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("stormpy") is None, reason="needs stormpy: pip install -e '.[prism]'"
)


@pytest.fixture(autouse=True)
def _storms_build(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests are about Storm's deferred build (the names and valuations of its
    second build), which the own parse would otherwise take over."""
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")

# Unlabelled commands in both modules (overlapping guards, one enabled nowhere), an
# action both modules synchronise on, an action of one module, and states without an
# enabled command (x=3: Storm's deadlock self-loop).
MODEL = """mdp
module robot
  x : [0..3] init 0;
  [] x=0 -> 0.5 : (x'=1) + 0.5 : (x'=2);
  [] x<2 -> (x'=x+1);
  [go] x=1 -> (x'=3);
  [sync] x=2 -> 0.25 : (x'=0) + 0.75 : (x'=3);
  [] x>5 -> (x'=0);
endmodule
module door
  d : [0..1] init 0;
  [] d=0 & x<2 -> (d'=1);
  [sync] true -> (d'=1-d);
endmodule
label "goal" = x=3 & d=1;
"""


def storm_names(path: Path) -> list[list[str]]:
    """Per state (Storm's order), its choices' names from Storm's choice origins."""
    import stormpy

    program = stormpy.parse_prism_program(str(path))
    commands = {}
    for module in program.modules:
        for k, cmd in enumerate(module.commands, start=1):
            commands[cmd.global_index] = (cmd.action_name if cmd.is_labeled else None,
                                          f"{module.name}_cmd{k}")
    options = stormpy.BuilderOptions()
    options.set_build_choice_origins()
    options.set_build_all_labels()
    model = stormpy.build_model(program, options=options)
    origins, matrix = model.choice_origins, model.transition_matrix
    out = []
    for s in range(model.nr_states):
        row = []
        for c in range(matrix.get_row_group_start(s), matrix.get_row_group_end(s)):
            found = [commands[i] for i in origins.get_command_set(c)]
            labelled = {a for a, _ in found if a is not None}
            row.append("deadlock" if not found else labelled.pop() if labelled
                       else found[0][1])
        out.append(row)
    return out


def test_names_on_demand_are_storms_choice_origins(tmp_path: Path) -> None:
    path = tmp_path / "m.prism"
    path.write_text(MODEL, encoding="utf-8")
    game = load_prism(path)
    names = game._tables.action_names
    assert not names.resolved  # Storm built no choice origins
    assert game.robot_actions() >= {"robot_cmd1", "robot_cmd2", "robot_cmd5", "door_cmd1"}
    want = storm_names(path)
    assert "deadlock" in {a for row in want for a in row}  # the model has a deadlock
    assert [list(game.actions(s)) for s in game.states] == want
    assert names.resolved
    # once named, the robot's actions are those used (robot_cmd5 is enabled nowhere)
    assert game.robot_actions() == {a for row in want for a in row}


def test_storms_own_loop_is_named_without_its_second_build(tmp_path: Path) -> None:
    """The first build has no choice labels (prism-copy): Storm's deadlock self-loop is
    named at once, every other choice (go, sync, the unlabelled commands') is late."""
    path = tmp_path / "m.prism"
    path.write_text(MODEL, encoding="utf-8")
    game = load_prism(path)
    t = game._tables
    known = np.flatnonzero(t.action_index < len(t.action_names))
    assert known.size  # the deadlock self-loop
    codes, table = t.action_names.names_of(known)
    assert {table[k] for k in codes.tolist()} == {"deadlock"}
    assert not t.action_names.resolved
    late = np.flatnonzero(t.action_index >= len(t.action_names))
    codes, table = t.action_names.names_of(late)
    assert {"go", "sync"} <= {table[k] for k in codes.tolist()}
    assert t.action_names.resolved


def _solve(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, at_once: bool) -> tuple:
    from mitld_lp import synthesize
    from mitld_lp.model import load_model
    from mitld_lp.solvers.export import write_drn
    from mitld_lp.worlds import prism_build

    with monkeypatch.context() as patch:
        if at_once:  # the first build with Storm's choice origins, as before
            patch.setattr(prism_build, "is_late", lambda program: False)
        (tmp_path / "m.prism").write_text(MODEL, encoding="utf-8")
        (tmp_path / "m.toml").write_text(
            'name = "m"\nspec = "F goal"\n\n[prism]\nfile = "m.prism"\n', encoding="utf-8")
        model = load_model(tmp_path / "m.toml")
        result = synthesize(model)
    mdp = result.mdp
    late = getattr(mdp.action_names, "resolved", None)
    assert late is (None if at_once else False)  # a solve reads no name
    copied = mdp.choice_actions.copy()  # ids taken before the names were made
    kind = "at_once" if at_once else "late"
    saved = tmp_path / f"{kind}.npz"
    result.controller.save(saved)
    drn = write_drn(mdp, mdp.target, tmp_path / f"{kind}.drn")
    policy = result.policy_table()
    return result, copied, dict(np.load(saved)), drn.read_text(encoding="utf-8"), policy


def test_a_controller_and_an_export_after_a_deferred_load(tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch
                                                          ) -> None:
    late, copied, controller, drn, policy = _solve(tmp_path, monkeypatch, False)
    now, _, controller_now, drn_now, policy_now = _solve(tmp_path, monkeypatch, True)
    assert (late.lower, late.upper) == (now.lower, now.upper)
    mdp = late.mdp
    assert tuple(mdp.action_names) == tuple(now.mdp.action_names)
    assert np.array_equal(mdp.choice_actions, now.mdp.choice_actions)
    assert set(controller) == set(controller_now)
    for key, array in controller.items():
        assert np.array_equal(array, controller_now[key]), key
    assert drn == drn_now and "robot_cmd" in drn
    assert policy == policy_now
    # an id copied before the names were made still names its choice
    names = [mdp.action_name(c) for c in range(mdp.n_choices)]
    assert [("absorb" if a < 0 else mdp.action_names[int(a)]) for a in copied] == names
    with pytest.raises(IndexError):  # out of range of a list made from the names
        list(mdp.action_names)[int(copied[copied >= 0][0])]


def test_two_choices_of_one_action_are_told_apart_when_named(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A module with two commands of one action: where both are enabled the two choices
    are ``go@robot_cmd3`` and ``go@robot_cmd4`` (their commands), named when first read
    as the load that names every choice at once names them."""
    from mitld_lp.worlds import prism_build

    path = tmp_path / "two.prism"
    path.write_text(MODEL.replace("[go] x=1 -> (x'=3);", "[go] x=1 -> (x'=3);\n"
                                  "  [go] x>=1 -> (x'=0);"), encoding="utf-8")
    game = load_prism(path)
    assert not game._tables.action_names.resolved
    late = [list(game.actions(s)) for s in game.states]
    with monkeypatch.context() as patch:
        patch.setattr(prism_build, "is_late", lambda program: False)
        now = load_prism(path)
    assert isinstance(now._tables.action_names, tuple)
    assert late == [list(now.actions(s)) for s in now.states]
    told = [row for row in late if "go@robot_cmd3" in row]
    assert told and all("go@robot_cmd4" in row and "go" not in row for row in told)
    # elsewhere the choices are Storm's origins' (one go choice: "go")
    want = storm_names(path)
    assert [[a.split("@")[0] for a in row] for row in late] == want


def test_an_action_named_as_a_command_is_named_at_once(tmp_path: Path) -> None:
    path = tmp_path / "named.prism"
    path.write_text(MODEL.replace("[go]", "[robot_cmd1]"), encoding="utf-8")
    game = load_prism(path)
    assert isinstance(game._tables.action_names, tuple)


def test_the_names_and_the_valuations_come_from_one_second_build(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.worlds import prism_names, prism_valuations

    builds: list[int] = []
    for module in (prism_names, prism_valuations):
        real = module.quiet_build
        monkeypatch.setattr(module, "quiet_build",
                            lambda *a, real=real, **k: builds.append(1) or real(*a, **k))
    path = tmp_path / "m.prism"
    path.write_text(MODEL, encoding="utf-8")
    want = storm_names(path)
    for read_first in ("names", "states"):
        game = load_prism(path)
        before = len(builds)
        if read_first == "names":
            assert [list(game.actions(game.states[0]))] == want[:1]  # the initial state
            assert len(builds) == before + 1
            assert game._tables.states.built
        else:
            assert len(list(game.states)) == len(want)
            assert len(builds) == before + 1
            assert game._tables.action_names.resolved
        assert [list(game.actions(s)) for s in game.states] == want
        assert len(builds) == before + 1


ROUTES = """mdp
module robot
  x : [0..4] init 0;
  [] x<3 -> 0.8 : (x'=x+1) + 0.2 : true;
  [] x<3 -> 0.5 : (x'=x+2) + 0.5 : (x'=0);
  [fast] x=1 -> (x'=3);
  [] x=3 -> 0.9 : (x'=4) + 0.1 : (x'=0);
  [] x=4 -> true;
endmodule
module other
  y : [0..1] init 0;
  [] y=0 & x=0 -> 0.5 : (y'=1) + 0.5 : true;
  [] y=1 -> (y'=0);
endmodule
label "goal" = x=4;
label "risky" = x=2;
"""


def _routes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, at_once: bool) -> list:
    from mitld_lp import synthesize
    from mitld_lp.model import load_model
    from mitld_lp.worlds import prism_build

    (tmp_path / "w.prism").write_text(ROUTES, encoding="utf-8")
    law = {"point": "0.5", "band": "[0.4, 0.6]"}
    for kind, mu in law.items():
        (tmp_path / f"{kind}.toml").write_text(
            'name = "w"\nspec = "D[mu] b & F(b & F[0,4] goal)"\n[prism]\nfile = "w.prism"\n'
            f"[distributions]\nmu = {{ geometric = {mu} }}\n", encoding="utf-8")
    out = []
    with monkeypatch.context() as patch:
        if at_once:
            patch.setattr(prism_build, "is_late", lambda program: False)
        for kind, options in (("point", {"constraints": ["P(F risky) <= 0.3"]}),
                              ("point", {"then": "min-steps"}), ("band", {}),
                              ("point", {"exact": True})):
            model = load_model(tmp_path / f"{kind}.toml")
            late = getattr(model.game._tables.action_names, "resolved", None)
            assert late is (None if at_once else False)
            result = synthesize(model, **options)
            saved = tmp_path / f"{kind}{len(out)}{at_once}.npz"
            result.controller.save(saved)
            out.append((result.lower, result.upper, result.policy_table(),
                        {k: v.tolist() for k, v in np.load(saved).items()}))
    return out


def test_the_other_routes_after_a_deferred_load(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Constraints, a lexicographic ``then``, a band and the exact answer: the same
    brackets, policies and controllers as after the load that names at once."""
    late = _routes(tmp_path, monkeypatch, False)
    assert late == _routes(tmp_path, monkeypatch, True)
    assert any("robot_cmd" in str(row["action"]) for row in late[0][2])
