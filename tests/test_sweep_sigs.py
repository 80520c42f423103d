"""The block kernel's helpers (mitld_lp.solvers.compiled_kernels) are compiled for one
signature each: the packing for one flag type (a constant True and False are two
literal types, two compiles), the bookkeeping after a sweep and the gap check for one
array layout (the packed rows passed whole with the guesses' column offset, not as the
slices ``work[:, :k]`` / ``work[:, k:]``, an 'A' layout compiled apart from the
C-contiguous bounds).  After solves that verify guesses, on one and two models, maximum
and minimum: each has one signature, no literal argument and C-contiguous arrays only,
and the bounds bracket the closed-form optimum as the NumPy sweeps' do."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import kernels
from mitld_lp.solvers.graph import Sense

numba = pytest.importorskip("numba")

# A ring of 10 states, two choices each, every state alike, so every state's value is
# its best choice's goal exit over its total exit (its ring steps keep it on the ring):
# A: +1 w.p. 0.5, -1 w.p. 0.497, goal 0.0018, fail 0.0012 -> goal 0.6, fail 0.4;
# B: +2 w.p. 0.3, -3 w.p. 0.6976, goal 0.0015, fail 0.0009 -> goal 0.625, fail 0.375.
N = 10
CHOICES = (((1, 0.5), (-1, 0.497), 0.0018, 0.0012),
           ((2, 0.3), (-3, 0.6976), 0.0015, 0.0009))
EXACT = {Sense.MAX: (0.625, 0.4), Sense.MIN: (0.6, 0.375)}
HELPERS = ("_pack", "_after_sweep", "_over", "_plain", "_watched", "_verifying", "verifying2",
           "watched2", "gauss_seidel")


def _ring() -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    rows, cols, vals, exits = [], [], [], []
    for s in range(N):
        for a, b, goal, fail in CHOICES:
            for step, p in (a, b):
                rows.append(len(exits)), cols.append((s + step) % N), vals.append(p)
            exits.append((goal, fail))
    inner = sp.csr_array((vals, (rows, cols)), shape=(len(exits), N))
    return inner, np.arange(0, 2 * N + 1, 2), np.array(exits)


@pytest.fixture(scope="module")
def solved() -> dict:
    """Each block solved by the compiled kernel (a call per sweep, and all sweeps in one
    call) and by the NumPy sweeps, for the goal alone (two columns) and both models."""
    if kernels.compiled_kernel() is None:
        pytest.skip("numba is not installed")
    inner, groups, exits = _ring()
    out: dict = {}
    for models in ((0,), (0, 1)):
        cols = exits[:, [m for m in models for _ in range(2)]]
        for sense in (Sense.MAX, Sense.MIN):
            for chunk in (1, 10_000):
                prep = kernels.Prepared(inner, groups)
                local = np.tile([0.0, 1.0], (N, len(models)))
                done, over = 0, np.inf
                while over >= 1.0 and done < 20_000:
                    swept, over = kernels.compiled_sweeps(prep, cols, local, 1e-9, chunk,
                                                          sense)
                    done += swept
                out[models, sense, chunk] = (local, over, prep.track.copy())
            local = np.tile([0.0, 1.0], (N, len(models)))
            _, over = kernels.numpy_sweeps(kernels.Prepared(inner, groups), cols, local,
                                           1e-9, 100_000, sense)
            out[models, sense, "numpy"] = (local, over, None)
    return out


def _signatures(name: str) -> set:
    """``name``'s signatures compiled in this process and those in numba's index on
    disk (a helper compiled inside the entry point is not listed in a process that
    loaded the entry point from the cache)."""
    from mitld_lp.solvers import compiled_kernels

    kernel = getattr(compiled_kernels, name)
    stored = [key[0] for key in kernel._cache._cache_file._load_index()]
    return {tuple(sig) for sig in [*kernel.signatures, *stored]}


def test_the_solves_verified_guesses(solved: dict) -> None:
    for key, (_, over, track) in solved.items():
        if track is not None:
            assert over < 1.0, key
            assert track[6] > 0 and track[3] >= 1, key  # verifying sweeps, a guess proven


@pytest.mark.parametrize("name", HELPERS)
def test_each_helper_has_one_signature(solved: dict, name: str) -> None:
    sigs = _signatures(name)
    assert len(sigs) == 1, sigs
    (sig,) = sigs
    assert not any(isinstance(t, numba.types.Literal) for t in sig), sig
    arrays = [t for t in sig if isinstance(t, numba.types.Array)]
    assert arrays and all(t.layout == "C" for t in arrays), sig


def test_bounds_bracket_the_closed_form_as_the_numpy_sweeps_do(solved: dict) -> None:
    for models in ((0,), (0, 1)):
        for sense in (Sense.MAX, Sense.MIN):
            numpy_local = solved[models, sense, "numpy"][0]
            for route in (1, 10_000, "numpy"):
                local, over, _ = solved[models, sense, route]
                assert over < 1.0
                for j, m in enumerate(models):
                    value = EXACT[sense][m]
                    lo, hi = local[:, 2 * j], local[:, 2 * j + 1]
                    assert np.all(lo <= value + 1e-15) and np.all(value - 1e-15 <= hi)
                    assert np.all(hi - lo <= 1e-9), (models, sense, route)
                # the same bracket as the NumPy sweeps' within the tolerance
                assert np.max(np.abs(local - numpy_local)) <= 2e-9
