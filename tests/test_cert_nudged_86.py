"""cert-86: the certificate's Bellman check refuses a value nudged out by one ulp.

Small MDPs with end components and rare values (``test_cert_small_exact``'s), their
exact optima in fractions (every deterministic policy's chain solved by Gauss-Jordan
elimination in rational arithmetic, the best kept a state at a time).  A candidate
upper vector at or above the maximum in every state but one ulp below it at one state
``s`` must fail the pre-fixed point check at ``s`` (the optimal row's exact sum there
is at least the maximum, above the candidate; the row's largest entry too, so the
convex rule cannot pass it either); a candidate lower vector at or below the minimum
but one ulp above it at ``s`` must fail the sub-fixed point check at ``s``.  The
compiled check and the NumPy check both, the same verdicts.  And the certificate
itself: its bracket holds the exact optimum, with the chain's compiled blocks gated
by the cache or not (the gate of cert-86), the same bits."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_small_exact import exact_optimum, paid_kernels, small_model

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_blocks as CB
from mitld_lp.solvers.certify_repair import Rows
from mitld_lp.solvers.rounding import rounding

N = 5
SEEDS = range(8)


def _up(q: Fraction) -> float:
    """The least float at or above ``q``."""
    f = float(q)
    return f if Fraction(f) >= q else math.nextafter(f, math.inf)


def _down(q: Fraction) -> float:
    """The greatest float at or below ``q``."""
    f = float(q)
    return f if Fraction(f) <= q else math.nextafter(f, -math.inf)


def _check(mdp, x: np.ndarray, upper: bool) -> np.ndarray:
    """The certificate's Bellman check's failing states for ``x``, the target and the
    sink free (their values fixed: 1 and 0)."""
    target = np.asarray(mdp.target, dtype=bool)
    free = target.copy()
    free[N + 1] = True  # the sink
    st = Rows(sp.csr_array(mdp.matrix), np.asarray(mdp.row_groups, dtype=np.int64))
    return C._fails(st, rounding(sp.csr_array(mdp.matrix), C.ETA), x, free, upper)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("upper", [True, False])
def test_a_value_nudged_out_by_an_ulp_is_refused(seed, upper, monkeypatch) -> None:
    mdp, exact = small_model(seed, N)
    v, _ = exact_optimum(mdp, exact, N, upper)
    # the states whose optimum an ulp can cross: a maximum above 0, a minimum below 1
    # and above 0 (a minimum of 0 may be a self-loop's, which any vector passes)
    asked = [s for s in range(N) if (v[s] > 0 if upper else 0 < v[s] < 1)]
    if not asked:
        pytest.skip("no state's optimum strictly inside")
    for s in asked:
        x = np.array([_up(q) if upper else _down(q) for q in v])
        x[s] = math.nextafter(_down(v[s]), -math.inf) if Fraction(_down(v[s])) == v[s] \
            else _down(v[s])
        if not upper:
            x[s] = math.nextafter(_up(v[s]), math.inf) if Fraction(_up(v[s])) == v[s] \
                else _up(v[s])
        assert (Fraction(x[s]) < v[s]) if upper else (Fraction(x[s]) > v[s])
        verdicts = []
        for compiled in (True, False):
            paid_kernels(monkeypatch, compiled)
            failing = _check(mdp, x, upper)
            assert failing[s], (seed, upper, s, v[s], x[s])
            verdicts.append(failing.tobytes())
        assert verdicts[0] == verdicts[1]  # the compiled check's verdicts are NumPy's


def _bracket(mdp, policy, v, upper: bool) -> tuple:
    """The certificate of ``policy`` told the exact zero (and one) sets: its bracket
    held against ``v[0]`` in fractions, and its bits."""
    cert = C.certify(mdp, np.asarray(mdp.target), policy, sense="max" if upper else "min",
                     zero=np.array([p == 0 for p in v]),
                     one=None if upper else np.array([p == 1 for p in v]))
    assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (upper, v[0], cert)
    assert cert.certified, [c.detail for c in cert.checks]
    return cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()


@pytest.mark.parametrize("seed", SEEDS)
def test_the_bracket_holds_the_exact_optimum_gate_or_not(seed, monkeypatch) -> None:
    mdp, exact = small_model(seed, N)
    paid_kernels(monkeypatch, True)
    for upper in (True, False):
        v, policy = exact_optimum(mdp, exact, N, upper)
        bits = set()
        for cached in (False, True):
            monkeypatch.setattr(CB, "_BLOCKS_WARM", [cached])
            bits.add(_bracket(mdp, policy, v, upper))
        assert len(bits) == 1
