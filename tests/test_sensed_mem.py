"""What the sensed product holds through its solve (issue 45's sensed case: 1.08M
transitions), checked on small sensed cases:

* the product's matrix keeps int32 columns and row pointers (as the plain product's),
  the states' columns and hypothesis codes a narrow copy of their own, and the
  builder's step tables are emptied once built: the answer read from that product is
  the optimum found here by a value iteration written in this file (dense, from
  below), which reads nothing of the package's solvers;
* the heap handed back after each LP (``routes/plain._trimmed``) for a product of at
  least ``TRIM_FROM_TRANSITIONS``: the same bracket, policy and values to the bit as
  without it, and one trim per LP."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

import mitld_lp.routes.plain as plain
import mitld_lp.util.heap as heap
from mitld_lp import load_model, synthesize
from mitld_lp.sensing import Sensor
from mitld_lp.sensing import frontier as frontier_module

MODELS = Path(__file__).resolve().parents[1] / "models"


def _bus(sensors: dict[str, float], epsilon: float):
    base = load_model(MODELS / "bus_grid.toml")
    return dataclasses.replace(base, epsilon=epsilon, sensors=MappingProxyType(
        {e: Sensor(d) for e, d in sensors.items()}))


def _reach_max_from_below(mdp) -> np.ndarray:
    """``Pmax(F target)`` with truncation losing (the lower model), by value iteration
    from 0 on the dense matrix until no value moves by more than 1e-15 (each iterate a
    lower bound on the optimum, converging to it)."""
    dense = mdp.matrix.toarray()  # (choices, states)
    groups = np.asarray(mdp.row_groups, dtype=np.int64)
    target = np.asarray(mdp.target, dtype=bool)
    state_of = np.repeat(np.arange(mdp.n_states), np.diff(groups))
    x = target.astype(float)
    for _ in range(100_000):
        per_choice = dense @ x
        best = np.full(mdp.n_states, -np.inf)
        np.maximum.at(best, state_of, per_choice)
        new = np.where(target, 1.0, np.maximum(best, 0.0))
        if np.max(np.abs(new - x)) <= 1e-15:
            return new
        x = new
    raise AssertionError("value iteration did not settle")


@pytest.mark.parametrize("sensors, epsilon", [({"b1": 0.5}, 0.01),
                                              ({"b1": 0.7, "b2": 0.7}, 0.05)])
def test_narrow_product_answers_the_brute_force_optimum(monkeypatch, sensors, epsilon):
    builders = []
    release = frontier_module.FrontierBuilder.release

    def kept(self):
        builders.append(self)
        release(self)

    monkeypatch.setattr(frontier_module.FrontierBuilder, "release", kept)
    r = synthesize(_bus(sensors, epsilon))
    assert r.route == "sensed" and r.certified
    m = r.mdp.matrix
    assert m.indices.dtype == np.int32 and m.indptr.dtype == np.int32
    states = r.mdp.states
    cols, codes, _ = states.columns()
    for a in (cols, codes):
        assert a.dtype.itemsize < 8  # narrowed
    # the posteriors and hypothesis counts read back whole from the narrowed columns
    counts = np.asarray(cols[5], dtype=np.int64)
    starts = np.asarray(cols[4], dtype=np.int64)
    live = counts > 0
    assert np.all(starts[live] + counts[live] <= len(codes))
    for i in np.flatnonzero(live)[:50].tolist():
        s = states[i]
        assert len(s.hypotheses) == counts[i]
        assert abs(sum(s.weights) - 1.0) < 1e-12
    (b,) = builders
    for table in (b.outcomes, b.branches, b.successors, b.actions):
        assert table.entries == [] and table.keyed is None
    best = _reach_max_from_below(r.mdp)[r.mdp.initial]
    # the certified lower end is the controller's value, within the precision of the
    # optimum; the upper end bounds the optimum with truncation winning
    assert r.lower <= best + 1e-9
    assert best - r.lower <= 1e-6 * max(best, 1e-300) + 1e-12
    assert best <= r.upper + 1e-12


def test_trims_after_each_lp_change_no_value(monkeypatch):
    model = _bus({"b1": 0.5}, 0.01)
    plain_run = synthesize(model)
    calls: list[str] = []
    monkeypatch.setattr(plain, "TRIM_FROM_TRANSITIONS", 0)  # every product is "large"
    monkeypatch.setattr(plain, "release_free_memory", lambda: calls.append("build") or True)
    monkeypatch.setattr(heap, "release_free_memory", lambda: calls.append("lp") or True)
    trimmed = synthesize(model)
    n_models = len({id(trimmed.lower_model), id(trimmed.upper_model)})
    assert n_models == 2  # truncated: both models solved, an LP each
    assert calls == ["build", "lp", "lp"]
    assert (trimmed.lower, trimmed.upper) == (plain_run.lower, plain_run.upper)
    for a, b in ((trimmed.lower_model, plain_run.lower_model),
                 (trimmed.upper_model, plain_run.upper_model)):
        assert np.array_equal(a.policy, b.policy)
        assert np.array_equal(a.policy_values, b.policy_values)
        assert a.bounds == b.bounds


def test_packed_runs_give_the_columns_back_to_the_bit():
    from mitld_lp.sensing.moves import PackedRuns

    rng = np.random.default_rng(7)
    runs = []
    for n in (0, 1, 5, 1000):
        runs.append((rng.integers(-3, 30_000, n).astype(np.int16),
                     rng.integers(0, 2**31 - 1, n).astype(np.int32),
                     rng.integers(-2**40, 2**40, n),  # int64
                     rng.integers(-100, 100, n).astype(np.int8)))
    back = PackedRuns(runs).unpack()
    assert len(back) == len(runs)
    for got, want in zip(back, runs, strict=True):
        assert len(got) == len(want)
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype and g.tolist() == w.tolist()
    assert PackedRuns(()).unpack() == ()
