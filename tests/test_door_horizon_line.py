"""The door's one-line answer says which model was solved: a product's size where one
was built, and that none was where the step-bounded reachability was solved over the
world (the horizon route's result reports the world's own sizes, which the line read as
a product's before)."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("stormpy")

from mitld_lp.cli import main  # noqa: E402

WALK = str(Path(__file__).parent / "data" / "door.prism")


def _line(capsys: pytest.CaptureFixture[str], prop: str) -> str:
    code = main(["solve", WALK, "-q", "--prop", prop, "--const", "N=4"])
    assert code == 0
    return capsys.readouterr().out


def test_a_long_step_bound_says_no_product_was_built(capsys) -> None:
    # 9 world states x 100,001 steps: a product bound past the horizon route's claim
    out = _line(capsys, 'Pmax=? [F<=100000 "goal"]')
    assert "no product" in out and "product states" not in out


def test_a_short_step_bound_reports_its_product(capsys) -> None:
    out = _line(capsys, 'Pmax=? [F<=3 "goal"]')
    assert "product states" in out and "no product" not in out
