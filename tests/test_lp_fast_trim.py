"""The plain route's trim before its LPs reaches the million-transition products: a
product of more than ``TRIM_FROM_TRANSITIONS`` transitions (the case study's task on a
64 x 64 grid with its hazards scaled, deadline 3: bench_sweeps' ``bus_scaled_n64_d3``,
whose peak is the LP stage's end) has the free heap handed back between the interval
iteration and its first LP, with the route's own thresholds (none patched).  The
trim's effect on the answer (none, to the bit) is checked on a small model in
``tests/test_bus_mem.py``; here the bracket is checked against an independent bound:
the same task with no deadline slack to spare is no easier (a shorter deadline cannot
raise the probability), solved with the trims off."""

from __future__ import annotations

import numpy as np
import pytest

from mitld_lp import GridWorld, Model, synthesize
from mitld_lp.routes import plain
from mitld_lp.solvers import lp as L

N = 64
SPEC = ("(D[geometric({p1})] b1 & F(b1 & F[0,{d}] A)) | "
        "(D[geometric({p2})] b2 & F(b2 & F[0,{d}] B))")


def _model(d: int) -> Model:
    """bench_scaling's ``bus_scaled`` instance of size ``N``, deadline ``d``."""
    p1, p2 = (round(p * 4.0 / N, 12) for p in (0.8, 0.3))
    world = GridWorld.make(N, N, start=(0, 0), slip=0.1,
                           regions={"A": [(N // 4, N // 2)], "B": [(N - 1, 0)]})
    return Model.from_game(world, SPEC.format(p1=repr(p1), p2=repr(p2), d=d), epsilon=0.01)


def test_million_transitions_trim_before_the_lp(monkeypatch: pytest.MonkeyPatch) -> None:
    events: list[str] = []
    solve_lp = L.solve_lp

    def traced_lp(*a, **k):  # type: ignore[no-untyped-def]
        events.append("lp")
        return solve_lp(*a, **k)

    iterate = plain._iterate

    def traced_iterate(*a, **k):  # type: ignore[no-untyped-def]
        events.append("iteration")
        return iterate(*a, **k)

    release = plain.release_free_memory

    def traced_release() -> bool:
        events.append("trim")
        return release()

    monkeypatch.setattr(L, "solve_lp", traced_lp)
    monkeypatch.setattr(plain, "_iterate", traced_iterate)
    monkeypatch.setattr(plain, "release_free_memory", traced_release)
    r = synthesize(_model(3))
    assert r.mdp.n_transitions > plain.TRIM_FROM_TRANSITIONS
    assert r.mdp.n_transitions < 4_000_000  # below the threshold the trim had before
    first_lp = events.index("lp")
    assert events[:first_lp] == ["trim", "iteration", "trim"]
    assert r.certified and r.lower <= r.upper
    # a shorter deadline is no easier: deadline 2's upper bound, solved with no trim
    # at all, is at most deadline 3's
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 10**18)
    monkeypatch.setattr(plain, "TRIM_BEFORE_LP_FROM", 10**18)
    shorter = synthesize(_model(2))
    assert shorter.certified
    assert np.float64(shorter.lower) <= np.float64(r.upper)
