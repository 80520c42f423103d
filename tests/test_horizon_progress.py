"""The step-bounded induction's progress bar: over the steps, in at least twenty looks,
closed at the end, and the bracket the same bits with or without it (the batches it
cuts the steps into change nothing but when the time and the bar are looked at)."""

from __future__ import annotations

import numpy as np
import pytest
from test_horizon_route import WALK_MOVES, arrays, induction

from mitld_lp.solvers import horizon
from mitld_lp.util.progress import bar, silenced


class Recorder:
    def __init__(self, **options):
        self.options, self.updates, self.closed = options, [], False

    def update(self, n=1):
        self.updates.append(n)

    def close(self):
        self.closed = True


@pytest.mark.parametrize("sense", ["max", "min"])
def test_the_bar_counts_every_step_and_the_bracket_is_unchanged(monkeypatch, sense) -> None:
    steps, goal = 97, np.array([s == 5 for s in range(6)])
    plain = horizon.horizon_reach(*arrays(WALK_MOVES), goal, np.ones(6, bool), steps, sense)
    made = []
    monkeypatch.setattr(horizon, "progress_bar",
                        lambda shown, **o: made.append(Recorder(shown=shown, **o)) or made[-1])
    shown = horizon.horizon_reach(*arrays(WALK_MOVES), goal, np.ones(6, bool), steps, sense,
                                  progress=True)
    (rec,) = made
    assert rec.options["total"] == steps and rec.options["shown"] is True and rec.closed
    assert sum(rec.updates) == steps and len(rec.updates) >= 20
    assert plain.lo.tobytes() == shown.lo.tobytes() and plain.hi.tobytes() == shown.hi.tobytes()
    exact = induction(WALK_MOVES, {5}, set(range(6)), steps, sense)[0]
    assert shown.lo[0] <= exact <= shown.hi[0]


def test_no_bar_under_silenced_whatever_is_asked() -> None:
    with silenced():
        assert type(bar(True, total=3)).__name__ == "_Off"


@pytest.mark.parametrize("given", [dict(method="vi"), dict(solver="HIGHS"),
                                   dict(backend="cvxpy"), dict(decompose=False)])
def test_a_setting_of_the_products_solve_keeps_the_product_route(tmp_path, monkeypatch,
                                                                  given) -> None:
    """An LP setting the horizon route would not read sends the problem to the product
    route, which reads it, instead of being dropped; the same problem without it is the
    horizon route's, and both brackets hold the exact induction."""
    pytest.importorskip("stormpy")
    from fractions import Fraction

    from test_horizon_route import walk_prism_model

    from mitld_lp import load_model, synthesize
    from mitld_lp.problem import Settings
    from mitld_lp.synthesis import pose

    monkeypatch.setattr("mitld_lp.routes.horizon.CLAIM_FROM", 1)
    model = load_model(walk_prism_model(tmp_path, "F[0,12] goal"))
    assert pose(model).route.name == "horizon"
    assert pose(model, settings=Settings(**given)).route.name == "plain"
    r = synthesize(model, **given)
    assert r.route == "plain" and r.certified
    assert pose(model).route.name == "horizon"
    h = synthesize(model)
    assert h.route == "horizon" and h.certified
    assert Fraction(max(r.lower, h.lower)) <= Fraction(min(r.upper, h.upper))
