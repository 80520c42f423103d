"""The PRISM load's transfer and archive reading (branch ``load-start``).

* The members of Storm's UMB archive read from the tar headers are :mod:`tarfile`'s
  (size and data offset of each), on Storm's own export and on archives in formats
  the reader hands to :mod:`tarfile` (pax headers, a long name).
* The capped child sends its result with the arrays out of band: arrays equal bit for
  bit, writable, of their dtype; an exception raised in the child is raised here; a
  child that dies before it has sent anything is a budget stop.
* What the load leaves for later is right when asked, through the capped child and in
  this process: each state's values, its labels and its actions' names, against
  Storm's own build with valuations and labels (its own calls, not the archive) and
  the action names worked out by hand for the program below.
* A PRISM solve in a fresh interpreter does not import :mod:`tarfile`.
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import signal
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.worlds import prism_archive, prism_bounded

ROOT = Path(__file__).resolve().parent.parent
needs_stormpy = pytest.mark.skipif(importlib.util.find_spec("stormpy") is None,
                                   reason="needs stormpy: pip install -e '.[prism]'")

# x's range (0..40) and b's give 82 valuations; 8 are reachable.  Module m has two
# commands without an action (m_cmd2, m_cmd3); [go] and [stay] synchronise with n.
PROGRAM = """mdp
module m
  x : [0..40] init 0;
  [go] x < 3 -> 0.5 : (x'=x+1) + 0.5 : (x'=x);
  [] x = 1 -> (x'=0);
  [] x < 3 -> 0.25 : (x'=3) + 0.75 : (x'=x);
  [stay] x = 3 -> true;
endmodule
module n
  b : bool init false;
  [go] true -> (b'=!b);
  [stay] true -> true;
endmodule
label "done" = x = 3;
label "odd" = x = 1;
"""


def _expected_actions(x: int) -> set[str]:
    """By hand from PROGRAM: [go] and m_cmd3 where x < 3, m_cmd2 at x = 1, [stay] at 3."""
    if x == 3:
        return {"stay"}
    return {"go", "m_cmd3"} | ({"m_cmd2"} if x == 1 else set())


def _members_by_tarfile(path: Path) -> dict[str, tuple[int, int, bool]]:
    with tarfile.open(path) as tar:
        return {t.name: (t.size, t.offset_data, t.isreg()) for t in tar.getmembers()}


def _mine(path: Path) -> dict[str, tuple[int, int, bool]]:
    return {k: (v.size, v.offset_data, v.regular)
            for k, v in prism_archive.members(str(path)).items()}


@needs_stormpy
def test_storms_archive_members_are_tarfiles(tmp_path):
    import stormpy
    import stormpy.io

    (tmp_path / "p.prism").write_text(PROGRAM, encoding="utf-8")
    program = stormpy.parse_prism_program(str(tmp_path / "p.prism"))
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_choice_labels()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    export = stormpy.io.UmbExportOptions()
    export.compression = stormpy.io.CompressionMode.NO_COMPRESSION
    path = tmp_path / "m.umb"
    stormpy.io.export_to_umb(model, str(path), options=export)
    expected = _members_by_tarfile(path)
    assert "branch-to-target.bin" in expected and "index.json" in expected
    assert prism_archive._read(str(path)) is not None  # the headers' own route
    assert _mine(path) == expected
    index = prism_archive.members(str(path))["index.json"]
    with tarfile.open(path) as tar:
        member = tar.extractfile("index.json")
        assert member is not None
        assert prism_archive.read_member(str(path), index) == member.read()


@pytest.mark.parametrize("form", [tarfile.PAX_FORMAT, tarfile.GNU_FORMAT, tarfile.USTAR_FORMAT])
def test_other_archives_are_read_as_tarfile_reads_them(tmp_path, form):
    path = tmp_path / "a.tar"
    # ustar: a name split into the header's prefix and name fields; else a long part
    long = ("d" * 60 + "/" + "e" * 60 + "/" + "x" * 50 + ".bin" if form == tarfile.USTAR_FORMAT
            else "d/" + "x" * 180 + ".bin")
    with tarfile.open(path, "w", format=form) as tar:
        for name, data in (("index.json", b"{}"), (long, bytes(range(256)) * 3),
                           ("e.bin", b"")):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    assert _mine(path) == _members_by_tarfile(path)


def _arrays() -> dict[str, object]:
    rng = np.random.default_rng(3)
    return {"f": rng.random(70_001), "i": np.arange(123_457, dtype=np.int64) * 3,
            "u": rng.integers(0, 255, size=(301, 7), dtype=np.uint8),
            "s": np.arange(10)[::2], "F": np.asfortranarray(rng.random((50, 3))),
            "t": ("a", frozenset({"b"}), 1.5)}


@pytest.mark.skipif(not prism_bounded.can_cap(), reason="no capped child on this platform")
def test_the_capped_childs_arrays_come_back_bit_for_bit():
    got = prism_bounded.run_capped(_arrays, 1 << 30)
    want = _arrays()
    assert got.keys() == want.keys() and got["t"] == want["t"]
    for key in ("f", "i", "u", "s", "F"):
        assert got[key].dtype == want[key].dtype and got[key].shape == want[key].shape
        assert got[key].tobytes() == want[key].tobytes()
        got[key][...] = 0  # writable, like an array unpickled in band
    assert got["F"].flags.f_contiguous and not got["F"].flags.c_contiguous  # its order kept
    with pytest.raises(KeyError, match="nothing here"):
        prism_bounded.run_capped(lambda: {}["nothing here"], 1 << 30)


def _killed() -> None:
    os.kill(os.getpid(), signal.SIGKILL)


@pytest.mark.skipif(not prism_bounded.can_cap(), reason="no capped child on this platform")
def test_a_child_that_dies_before_sending_is_a_budget_stop():
    with pytest.raises(prism_bounded.OutOfBudget, match="SIGKILL"):
        prism_bounded.run_capped(_killed, 1 << 30)


def _storm_values(model: object, s: int) -> dict[str, object]:
    """State ``s``'s values by Storm's own per-variable calls."""
    values = model.state_valuations  # type: ignore[attr-defined]
    return {v.name: (bool(values.get_boolean_value(s, v)) if v.has_boolean_type()
                     else int(values.get_int64_value(s, v)))
            for v in values.get_all_variables()}


@needs_stormpy
@pytest.mark.parametrize("max_states", [50, 10_000])  # 82 valuations: capped child; here
def test_what_the_load_leaves_for_later_is_right_when_asked(tmp_path, monkeypatch,
                                                           max_states):
    import stormpy

    from mitld_lp.worlds import prism_build
    from mitld_lp.worlds.prism import load_prism

    capped = []

    def counted(work, budget):
        capped.append(budget)
        return prism_bounded.run_capped(work, budget)

    monkeypatch.setattr(prism_build, "run_capped", counted)
    monkeypatch.setenv("MITLD_PRISM_BUILDER", "storm")  # about Storm's build: forced
    prism = tmp_path / "p.prism"
    prism.write_text(PROGRAM, encoding="utf-8")
    game = load_prism(prism, max_states=max_states)
    assert len(capped) == (1 if max_states < 82 and prism_bounded.can_cap() else 0)
    # left for later: the values and the names of the commands without an action
    assert not game.states.built
    assert type(game._tables.action_names).__name__ == "DeferredNames"
    initial = game.initial  # known without the values (Storm's build of one state)
    assert not game.states.built

    program = stormpy.parse_prism_program(str(prism))
    options = stormpy.BuilderOptions()
    options.set_build_all_labels()
    options.set_build_state_valuations()
    model = stormpy.build_model(program, options=options)
    assert len(game.states) == model.nr_states == 8
    first = _storm_values(model, model.initial_states[0])
    assert game.valuation(initial) == first == {"x": 0, "b": False}
    for s in range(model.nr_states):
        storm = _storm_values(model, s)
        state = game.states[s]
        assert game.valuation(state) == storm
        labels = set(model.labeling.get_labels_of_state(s)) & {"done", "odd"}
        assert game.propositions(state) == frozenset(labels)
        assert set(game.actions(state)) == _expected_actions(storm["x"])
        assert len(game.actions(state)) == model.get_nr_available_actions(s)
    assert game.states.built
    assert game.robot_actions() == {"go", "stay", "m_cmd2", "m_cmd3"}


@needs_stormpy
def test_a_prism_solve_does_not_import_tarfile(tmp_path):
    (tmp_path / "p.prism").write_text(PROGRAM.replace("[0..40]", "[0..3]"), encoding="utf-8")
    (tmp_path / "p.toml").write_text('name = "p"\nspec = "F done"\n\n[prism]\nfile = "p.prism"\n',
                                     encoding="utf-8")
    probe = ("import json, sys\nfrom mitld_lp import load_model, synthesize\n"
             "r = synthesize(load_model(sys.argv[1]))\n"
             "print(json.dumps({'lower': r.lower, 'upper': r.upper,\n"
             "                  'tarfile': 'tarfile' in sys.modules,\n"
             "                  'read': 'mitld_lp.worlds.prism_archive' in sys.modules}))")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "PYTHONDONTWRITEBYTECODE": "1"}
    out = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "p.toml")], cwd=tmp_path,
                         capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["read"] and not got["tarfile"]
    # F done: m_cmd3 from x = 0 reaches x = 3 with 0.25 and stays with 0.75: 1 by repeating
    assert got["upper"] >= 1 - 1e-9 and got["lower"] >= 1 - 1e-6
