"""cert-78: the chain's sets and its solved states' chain by one compiled call
(``certify_kernels.chain_parts`` through ``certify_compiled.compiled_chain_parts``),
in place of the NumPy gather of :func:`~mitld_lp.solvers.certify_chain.chain`.

The arrays are held against a construction written here a row and an entry at a time
in Python (the sets by a forward fixpoint on a dense adjacency, ``b`` a sum from 0 in
the row's order, the chain's entries appended one by one), and against the NumPy
gather (the same values, order and index types).  The brackets of certificates that
ran the compiled call are held against the exact optimum computed by brute force in
rational arithmetic (``Fraction``: every deterministic policy solved exactly,
``test_cert_small_exact``)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from test_cert_small_exact import SEEDS, N, chain_case, paid_kernels, sets_by_fixpoint, small_model
from test_cert_small_exact import exact_optimum as _exact_optimum

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain, certify_compiled


def _parts_by_hand(m, states, rows, target):
    """``(never, sure, idx, b, vals, cols, ptr)`` as lists, an entry at a time."""
    never, sure = sets_by_fixpoint(m, states, rows, target)
    solved = [int(s) for s in states if not never[s] and not sure[s]]
    at = {s: k for k, s in enumerate(solved)}
    row_of = dict(zip(states.tolist(), rows.tolist(), strict=True))
    b, vals, cols, ptr = [], [], [], [0]
    for s in solved:
        acc = 0.0
        r = row_of[s]
        for e in range(int(m.indptr[r]), int(m.indptr[r + 1])):
            p, c = float(m.data[e]), int(m.indices[e])
            if not p > 0.0:
                continue
            if sure[c]:
                acc += p
            elif c in at:
                vals.append(p)
                cols.append(at[c])
        b.append(acc)
        ptr.append(len(vals))
    return never, sure, solved, b, vals, cols, ptr


@pytest.mark.parametrize("seed", range(12))
def test_compiled_chain_parts_are_the_entries_one_by_one(seed, monkeypatch) -> None:
    case = chain_case(seed)
    want = _parts_by_hand(*case)
    by_path = {}
    for compiled in (False, True):  # refused where no kernel's load is paid
        paid_kernels(monkeypatch, compiled)
        by_path[compiled] = certify_compiled.compiled_chain_parts(*case)
    assert by_path[False] is None and by_path[True] is not None
    m, states, rows, target = case
    got = by_path[True]
    never, sure, idx, b, vals, cols, ptr = got
    assert np.array_equal(never, want[0]) and np.array_equal(sure, want[1])
    assert idx.tolist() == want[2] and cols.tolist() == want[5] and ptr.tolist() == want[6]
    # the same bits: the sums and values compared as their hex digits
    assert [x.hex() for x in b.tolist()] == [x.hex() for x in want[3]]
    assert [x.hex() for x in vals.tolist()] == [x.hex() for x in want[4]]
    assert idx.dtype == cols.dtype == ptr.dtype == np.int32
    # and what the NumPy gather of the chain makes of the same sets
    solved = np.zeros(target.size, dtype=bool)
    solved[idx] = True
    policy = np.full(target.size, -1, dtype=np.int64)
    policy[states] = rows
    if idx.size:
        nb, sub = certify_chain._gathered(m, policy, idx, solved, sure, np.int32)
        assert nb.tobytes() == b.tobytes()
        assert sub.data.tobytes() == vals.tobytes()
        assert np.array_equal(sub.indices, cols) and np.array_equal(sub.indptr, ptr)
        assert sub.indices.dtype == cols.dtype and sub.indptr.dtype == ptr.dtype


def test_compiled_chain_parts_refuse_states_out_of_order(monkeypatch) -> None:
    m, states, rows, target = chain_case(0)
    paid_kernels(monkeypatch, True)
    assert certify_compiled.compiled_chain_parts(m, states[::-1].copy(), rows[::-1].copy(),
                                                 target) is None


def _bracket(mdp, target, v, policy, upper, compiled, monkeypatch):
    """The certificate's bracket and values (hex digits, bytes) with the compiled paths
    on or off, and whether its chain came from the compiled call."""
    ran = []
    real = certify_compiled.compiled_chain_parts
    monkeypatch.setattr(certify_chain, "compiled_chain_parts",
                        lambda *a: ran.append(real(*a)) or ran[-1])
    paid_kernels(monkeypatch, compiled)
    cert = C.certify(mdp, target, policy, sense="max" if upper else "min",
                     zero=np.array([p == 0 for p in v]),
                     one=None if upper else np.array([p == 1 for p in v]))
    assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (upper, v[0])
    assert cert.certified, [c.detail for c in cert.checks]
    return ((cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()),
            [r is not None for r in ran])


@pytest.mark.parametrize("upper", (True, False))
@pytest.mark.parametrize("seed", SEEDS)
def test_brackets_from_the_compiled_chain_parts_hold_the_exact_optimum(
        seed, upper, monkeypatch) -> None:
    """Certificates whose chain came from the compiled call (checked: it returned
    arrays) bracket the brute force's exact optimum, with the bits of the NumPy path."""
    mdp, exact = small_model(seed, N)
    v, policy = _exact_optimum(mdp, exact, N, upper)
    target = np.asarray(mdp.target)
    on, ran_on = _bracket(mdp, target, v, policy, upper, True, monkeypatch)
    off, ran_off = _bracket(mdp, target, v, policy, upper, False, monkeypatch)
    assert ran_on == [True] and ran_off == [False]
    assert on == off
