"""``mitld-lp export MODEL --controller/--chain/--tree``: the files the library writes,
from the command line; the chain is checked by Storm against the synthesis's ``lower``
(an independent route), the controller file is loaded and acts, a band is refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mitld_lp import synthesize
from mitld_lp.cli import main
from mitld_lp.controllers.kinds import load_controller
from mitld_lp.model import load_model

MODELS = Path(__file__).resolve().parent.parent / "models"


def test_export_writes_the_controller_the_chain_and_the_tree(tmp_path, capsys) -> None:
    from test_chain import storm_accept

    out = {k: tmp_path / f"bus.{k}" for k in ("npz", "drn", "json")}
    code = main(["export", str(MODELS / "bus_grid.toml"), "--controller", str(out["npz"]),
                 "--chain", str(out["drn"]), "--tree", str(out["json"]), "-q"])
    assert code == 0
    lower = synthesize(load_model(MODELS / "bus_grid.toml")).lower
    assert storm_accept(out["drn"]) == pytest.approx(lower, abs=1e-9)
    assert load_controller(out["npz"]).randomised is False
    tree = json.loads(out["json"].read_text())
    assert tree["nodes"] and tree["features"][:2] == ["x", "y"]
    assert "nodes over" in capsys.readouterr().out
    # the files exist now: refused before any work without --force
    assert main(["export", str(MODELS / "bus_grid.toml"), "--tree", str(out["json"]),
                 "-q"]) == 2


def test_export_of_a_constrained_model_writes_the_randomised_controller(tmp_path) -> None:
    from test_chain import storm_accept

    text = (MODELS / "bus_risk.toml").read_text()
    model = tmp_path / "risk.toml"
    model.write_text('constraints = ["P(F puddle) <= 0.05"]\n' + text)
    code = main(["export", str(model), "--controller", str(tmp_path / "r.npz"),
                 "--chain", str(tmp_path / "r.drn"), "-q"])
    assert code == 0
    assert load_controller(tmp_path / "r.npz").randomised
    want = synthesize(load_model(model)).lower
    assert storm_accept(tmp_path / "r.drn") == pytest.approx(want, abs=1e-9)


def test_export_refusals_name_the_combination(tmp_path, capsys) -> None:
    # a band's --chain is written now (tests/test_band_chain.py), with constraints refused
    assert main(["export", str(MODELS / "bus_grid.toml"), "--same-actions", "--lp",
                 str(tmp_path / "x.lp"), "-q"]) == 2
    assert "--same-actions" in capsys.readouterr().err
    assert main(["export", str(MODELS / "bus_grid.toml"), "--tree",
                 str(tmp_path / "t.txt"), "-q"]) == 2
    assert main(["export", str(MODELS / "bus_grid.toml"), "--upper", "--chain",
                 str(tmp_path / "u.drn"), "-q"]) == 2
    assert not any(tmp_path.iterdir())
