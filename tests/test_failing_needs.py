"""A maximum's Bellman check by the repair's kernel asked for verdicts
(:func:`mitld_lp.solvers.certify_compiled.compiled_failing`) against the check it
replaces: on random models (robust rows of nature among them, empty rows, tied values
of ``x``, odd stored values) the same failing states as the compiled check and the
NumPy check, and as the check's definition evaluated here a row at a time (the
rounded sum in the row's order, the convex rule's extreme compared in exact
rationals); where the check's segmented reductions read other rows (a state with no
choice, rows beyond the states') or ``x`` is not finite, the check runs."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as hs
from test_cert_verdicts_84 import definition

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers.rounding import rounding
from mitld_lp.util import kernel_loader

TIES = (0.0, 0.25, 0.5, 0.75, 1.0)


@hs.composite
def models(draw):
    """``(st, x, free)``: a model of 1-8 states, 1-3 choices a state, 1-3 rows of
    nature a choice (or one row a choice), 0-4 entries a row (dyadic or random
    probabilities), and a candidate ``x`` of tied or random values."""
    n = draw(hs.integers(1, 8))
    robust = draw(hs.booleans())
    seed = draw(hs.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    choices = rng.integers(1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(choices)]).astype(np.int64)
    n_choices = int(groups[-1])
    per_choice = rng.integers(1, 4, size=n_choices) if robust else np.ones(n_choices, int)
    nature = np.concatenate([[0], np.cumsum(per_choice)]).astype(np.int64)
    n_rows = int(nature[-1])
    ptr, cols, vals = [0], [], []
    dyadic = draw(hs.booleans())
    for _ in range(n_rows):
        k = int(rng.integers(0, 5))
        c = np.sort(rng.choice(n, size=min(k, n), replace=False))
        p = rng.integers(1, 5, size=c.size) / 4.0 if dyadic else rng.random(c.size)
        if c.size:
            p = p / p.sum()
        cols.extend(c.tolist())
        vals.extend(p.tolist())
        ptr.append(len(cols))
    m = sp.csr_array((np.asarray(vals, dtype=np.float64), np.asarray(cols, dtype=np.int32),
                      np.asarray(ptr, dtype=np.int32)), shape=(n_rows, n))
    st = C.Rows(m, groups, nature if robust else None)
    x = (rng.choice(TIES, size=n) if draw(hs.booleans()) else rng.random(n)).astype(float)
    free = rng.random(n) < 0.2
    return st, x, free


def _present(st, rnd, x, free, compiled: bool) -> np.ndarray:
    """The present check (:func:`certify._fails`), compiled or NumPy, the needs off."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(C, "compiled_failing", lambda *a, **k: None)
        mp.setattr(kernel_loader, "compiled_paid", lambda: compiled)
        mp.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 0)
        return C._fails(st, rnd, x, free, True)


def _from_needs(st, rnd, x, free, states=None) -> np.ndarray | None:
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(kernel_loader, "compiled_paid", lambda: True)
        mp.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 0)
        return CC.compiled_failing(st, rnd, x, free, states)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models())
def test_needs_give_the_checks_verdicts(model) -> None:
    st, x, free = model
    rnd = rounding(st.matrix)
    got = _from_needs(st, rnd, x, free)
    assert got is not None
    want = definition(st, rnd, x, free, True)  # (test_cert_verdicts_84's: both sides)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got, _present(st, rnd, x, free, compiled=True))
    np.testing.assert_array_equal(got, _present(st, rnd, x, free, compiled=False))
    # on some states alone (:func:`certify._fails_among`): theirs, the others passing
    among = np.flatnonzero(np.arange(st.n_states) % 2 == 0)
    part = _from_needs(st, rnd, x, free, among)
    only = np.zeros(st.n_states, dtype=bool)
    only[among] = want[among]
    np.testing.assert_array_equal(part, only)


def _small():
    m = sp.csr_array((np.array([0.5, 0.5, 1.0]), np.array([0, 1, 1], dtype=np.int32),
                      np.array([0, 2, 3], dtype=np.int32)), shape=(2, 2))
    return C.Rows(m, np.array([0, 1, 2], dtype=np.int64))


def test_where_verdicts_could_part_the_check_runs() -> None:
    """A value of ``x`` not finite (the compiled check refuses it too), a state with no
    choice, rows beyond the states': no verdict from the kernel."""
    st = _small()
    rnd = rounding(st.matrix)
    free = np.zeros(2, dtype=bool)
    assert _from_needs(st, rnd, np.array([0.5, 0.5]), free) is not None
    for bad in ([np.nan, 0.5], [np.inf, 0.5]):
        assert _from_needs(st, rnd, np.array(bad), free) is None
    no_choice = C.Rows(st.matrix, np.array([0, 0, 2], dtype=np.int64))
    assert _from_needs(no_choice, rnd, np.array([0.5, 0.5]), free) is None
    short = C.Rows(st.matrix, np.array([0, 1], dtype=np.int64))
    assert _from_needs(short, rnd, np.array([0.5]), np.zeros(1, dtype=bool)) is None


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(models(), hs.sampled_from([np.nan, np.inf, -np.inf, -0.5, 1e308]),
       hs.sampled_from([-0.25, 2.0]))
def test_odd_values_give_the_checks_verdicts(model, entry, below) -> None:
    """A stored value NaN, infinite, negative or huge (a NaN bound goes on to the convex
    rule, as in the check), a negative or above-1 ``x``: the compiled and the NumPy
    check's verdicts."""
    st, x, free = model
    m = st.matrix.copy()
    if m.nnz:
        m.data[0] = entry
    st = C.Rows(m, st.groups, st.nature)
    x = x.copy()
    x[0] = below
    rnd = rounding(st.matrix)
    got = _from_needs(st, rnd, x, free)
    assert got is not None
    with np.errstate(all="ignore"):
        np.testing.assert_array_equal(got, _present(st, rnd, x, free, compiled=True))
        np.testing.assert_array_equal(got, _present(st, rnd, x, free, compiled=False))


def test_a_maximums_check_links_no_check_kernel(monkeypatch) -> None:
    """:func:`certify._fails` and :func:`certify._fails_among` read the needs, not the
    compiled check, where the needs run: above, and below since cert-84."""
    st = _small()
    rnd = rounding(st.matrix)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 0)
    called = []
    real = C.compiled_checks
    monkeypatch.setattr(C, "compiled_checks",
                        lambda *a, **k: called.append(a[-1] if len(a) > 5 else None)
                        or real(*a, **k))
    x, free = np.array([0.25, 0.5]), np.zeros(2, dtype=bool)
    # state 0 reads 0.25 < (0.25 + 0.5) / 2: it fails; state 1 stays at 0.5: it passes
    np.testing.assert_array_equal(C._fails(st, rnd, x, free, True), [True, False])
    np.testing.assert_array_equal(
        C._fails_among(st, rnd, x, free, True, np.array([True, True])), [True, False])
    assert called == []
    # below: state 0's sum 0.375 is at least 0.25; state 1 passes by the rule
    np.testing.assert_array_equal(C._fails(st, rnd, x, free, False), [False, False])
    assert called == []
