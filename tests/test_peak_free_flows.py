"""The LP's flows (``LPResult.occupancy`` and ``.randomized``, two floats a choice of the
product) left out where nobody reads them: ``solve_lp(..., flows=False)`` gives the same
values and policy to the bit as the call that makes them, and the plain route asks for
no flows, so none is alive while its certificates run (where memory peaks)."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.solvers import analysis
from mitld_lp.solvers import lp as L
from mitld_lp.solvers.evaluation import evaluate_policy
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.result import LPResult
from mitld_lp.testing import random_mdp

BUS_GRID = Path(__file__).resolve().parent.parent / "models" / "bus_grid.toml"
STORM = 0.9244053  # Storm's value of models/bus_grid.toml (tests/test_lp.py)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_no_flows_same_answer_to_the_bit(seed: int, sense: Sense) -> None:
    mdp = random_mdp(200, seed=seed, locality=None if seed % 2 else 10)
    q = analysis.analyse(mdp, mdp.target, sense=sense)[0]
    it = interval_iteration(mdp, mdp.target, quotient=q, sense=sense, tol=1e-10,
                            precision=None, gap="max")
    got = {f: L.solve_lp(mdp, mdp.target, quotient=q, sense=sense, everywhere=True,
                         bounds=(it.lower, it.upper), flows=f) for f in (True, False)}
    full, bare = got[True], got[False]
    assert full.occupancy is not None and full.randomized is not None
    assert bare.occupancy is None and bare.randomized is None
    assert bare.status is full.status
    assert bare.policy.tobytes() == full.policy.tobytes()
    assert bare.values.tobytes() == full.values.tobytes()
    for f in ("value", "primal_objective", "dual_objective"):
        assert np.float64(getattr(bare, f)).tobytes() == np.float64(getattr(full, f)).tobytes()
    # the policy is a good one, by an independent evaluation of its chain
    value = evaluate_policy(mdp, mdp.target, bare.policy)
    i = mdp.initial
    assert it.lower[i] - 1e-8 <= value[i] <= it.upper[i] + 1e-8


def _lp_records() -> list[LPResult]:
    # a weak proxy whose object is gone raises on isinstance (numba's recompile, in an
    # earlier test of the worker, leaves some): not an LP record either way
    return [o for o in gc.get_objects()
            if not isinstance(o, weakref.ProxyTypes) and isinstance(o, LPResult)]


def test_plain_route_holds_no_flows_at_its_certificates(monkeypatch) -> None:
    """Every LP record alive while a certificate runs (the peak) has no occupancy; the
    answers are those of the solve that made the flows (forced on), to the bit."""
    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import certify as C

    model = load_model(BUS_GRID)
    seen: list[list[LPResult]] = []
    real = C.certify

    def watching(*args, **kwargs):
        seen.append(_lp_records())
        return real(*args, **kwargs)

    monkeypatch.setattr(C, "certify", watching)
    now = synthesize(model)
    assert seen and all(seen)  # the certificates ran, each with an LP record alive
    assert all(r.occupancy is None and r.randomized is None for rs in seen for r in rs)
    # the same solve with the flows made, as before
    solve = L.solve_lp
    monkeypatch.setattr(L, "solve_lp", lambda *a, **k: solve(*a, **{**k, "flows": True}))
    seen.clear()
    before = synthesize(model)
    assert any(r.occupancy is not None for rs in seen for r in rs)  # the test can fail
    assert np.float64(now.lower).tobytes() == np.float64(before.lower).tobytes()
    assert np.float64(now.upper).tobytes() == np.float64(before.upper).tobytes()
    for a, b in ((now.lower_model, before.lower_model), (now.upper_model, before.upper_model)):
        assert a.policy.tobytes() == b.policy.tobytes()
        assert a.policy_values.tobytes() == b.policy_values.tobytes()
        assert a.bounds == b.bounds
    assert now.certified and now.lower <= STORM + 1e-7 and STORM - 1e-7 <= now.upper
