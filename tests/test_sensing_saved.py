"""A controller that acts on sensor reports, saved and loaded: the loaded one (tables
only, no world) makes the same choices as the synthesised one on the same runs; foreign
or damaged files are refused naming the file; ``export --controller`` writes it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_sensing import SPEC, STATION

from mitld_lp import Model, load_model, synthesize
from mitld_lp.controllers.format import ControllerFileError
from mitld_lp.sensing.observe import simulate_sensed
from mitld_lp.sensing.saved import load_sensed

GRID = Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml"


@pytest.mark.parametrize("sensors", [{"b": {"detect": 0.5}},
                                     {"b": {"detect": 0.7, "delay": 1}}])
def test_loaded_controller_plays_the_same(tmp_path: Path, sensors: dict) -> None:
    model = Model.from_game(STATION, SPEC, sensors=sensors)
    r = synthesize(model)
    path = r.controller.save(tmp_path / "c.npz")
    loaded = load_sensed(path)
    assert loaded.game is None
    a = simulate_sensed(model, r.controller, runs=500, seed=11)
    b = simulate_sensed(model, loaded, runs=500, seed=11)
    assert a == b
    with pytest.raises(FileExistsError):
        r.controller.save(path)


def test_bus_grid_with_a_camera_round_trip(tmp_path: Path) -> None:
    text = GRID.read_text() + "\n[sensors]\nb1 = { detect = 0.6 }\n"
    model_file = tmp_path / "bus.toml"
    model_file.write_text(text)
    out = tmp_path / "c.npz"
    run = subprocess.run([sys.executable, "-m", "mitld_lp", "export", "--controller",
                          str(out), "--epsilon", "0.05", str(model_file)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    model = load_model(model_file)
    r = synthesize(model, epsilon=0.05)
    a = simulate_sensed(model, r.controller, runs=200, seed=2)
    b = simulate_sensed(model, load_sensed(out), runs=200, seed=2)
    assert a == b


def test_foreign_and_damaged_files_refused(tmp_path: Path) -> None:
    bad = tmp_path / "x.npz"
    bad.write_bytes(b"not an archive")
    with pytest.raises(ControllerFileError, match="x.npz: cannot load the controller"):
        load_sensed(bad)
    np.savez(bad, meta=np.zeros(3, dtype=np.uint8))
    with pytest.raises(ControllerFileError, match="not a controller archive"):
        load_sensed(bad)
    r = synthesize(Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}}))
    good = r.controller.save(tmp_path / "c.npz")
    with np.load(good) as f:
        arrays = {k: f[k] for k in f.files}
    arrays["moves"] = arrays["moves"].copy()
    arrays["moves"][0, 4] = 10**6
    np.savez(bad, **arrays)
    with pytest.raises(ControllerFileError, match="next state out of range"):
        load_sensed(bad)


def test_load_controller_loads_every_kind_of_controller_file(tmp_path: Path) -> None:
    """One loader for every controller file: it named load_sensed and refused a sensed
    controller; now it loads it and the loaded one plays as the synthesised one.  One
    reader (issue 42): the deterministic controllers' reader refused it ("sensor
    reports"); the reader reads every kind, and a class's own loader names the kind."""
    from mitld_lp import Controller, load_controller
    from mitld_lp.controllers.reader import read
    from mitld_lp.controllers.tables import SensedPlan

    model = Model.from_game(STATION, SPEC, sensors={"b": {"detect": 0.5}})
    r = synthesize(model)
    path = r.controller.save(tmp_path / "c.npz")
    loaded = load_controller(path)
    assert simulate_sensed(model, loaded, runs=300, seed=5) == simulate_sensed(
        model, r.controller, runs=300, seed=5)
    assert isinstance(read(path), SensedPlan)
    with pytest.raises(ControllerFileError, match="a sensed controller; load it with"):
        Controller.load(path)
