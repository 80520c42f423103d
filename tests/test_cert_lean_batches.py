"""The certificate's pieces read a batch of states at a time (cert-lean): the minimum's
test for states that may hold an end component (``certify_chain.cycling_among``) and
the compiled Bellman check of every state (``certify_compiled.compiled_checks``).
Whatever the batch, each gives what a plain loop written here gives (the first), or
the NumPy check's verdict on every row (the second, another route to the same
verdicts)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_chain, certify_compiled
from mitld_lp.solvers.rounding import rounding


def _model(seed: int, nature: bool = False) -> tuple[sp.csr_array, np.ndarray, np.ndarray]:
    """A random matrix of choices grouped into states (some with none, some choices
    staying put: every entry in the state's own column), nature's rows per choice where
    asked, and the choices' rows pointers."""
    rng = np.random.default_rng(seed)
    n = 37
    per = rng.integers(0 if not nature else 1, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    n_choices = int(groups[-1])
    per_choice = rng.integers(1, 3, size=n_choices) if nature else np.ones(n_choices,
                                                                           dtype=np.int64)
    nat = np.concatenate([[0], np.cumsum(per_choice)]).astype(np.int64)
    owner = np.repeat(np.arange(n), per)
    data, cols, ptr = [], [], [0]
    for r in range(int(nat[-1])):
        s = int(owner[np.searchsorted(nat, r, side="right") - 1])
        kind = rng.random()
        if kind < 0.25:
            succ = [s] * int(rng.integers(1, 3))
        elif kind < 0.35:
            succ = [s, (s + 1 + int(rng.integers(0, n - 1))) % n]
        else:
            succ = sorted(rng.choice(n, size=int(rng.integers(1, 4)), replace=False).tolist())
        cols += succ
        data += rng.dirichlet(np.ones(len(succ))).tolist()
        ptr.append(len(cols))
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(int(nat[-1]), n))
    return m, groups, nat


@pytest.mark.parametrize("seed", range(8))
def test_cycling_among_in_batches_is_a_plain_loop(seed, monkeypatch) -> None:
    m, groups, _ = _model(seed)
    n = groups.size - 1
    rng = np.random.default_rng(50 + seed)
    comp = rng.integers(0, n, size=n)  # some components of two states or more
    left = rng.random(n) < 0.7
    size = np.bincount(comp, minlength=n)
    want = np.zeros(n, dtype=bool)
    for s in range(n):  # in ``left``, and in a large component or with a choice that stays
        if not left[s]:
            continue
        stays = False
        for c in range(int(groups[s]), int(groups[s + 1])):
            entries = m.indices[m.indptr[c]:m.indptr[c + 1]].tolist()
            stays |= bool(entries) and all(j == s for j in entries)
        want[s] = size[comp[s]] > 1 or stays
    assert want.any() and not want.all()
    for batch in (1, 2, 5, 1 << 15):
        monkeypatch.setattr(certify_chain, "CYCLING_BATCH", batch)
        assert np.array_equal(certify_chain.cycling_among(m, groups, comp, left), want)


@pytest.mark.parametrize("nature", [False, True])
@pytest.mark.parametrize("seed", range(6))
def test_compiled_check_in_batches_gives_numpys_verdicts(seed, nature, monkeypatch) -> None:
    m, groups, nat = _model(seed, nature)
    st = C.Rows(m, groups, nat if nature else None)
    rng = np.random.default_rng(seed)
    x = rng.random(groups.size - 1)
    x[rng.random(x.size) < 0.2] = x.max()
    free = rng.random(x.size) < 0.1
    rnd = rounding(m)
    monkeypatch.setattr(certify_compiled, "kernel_loader",
                        SimpleNamespace(compiled_paid=lambda: True))
    monkeypatch.setattr(certify_compiled, "COMPILED_CHECK_MIN_ROWS", 0)
    for upper in (True, False):
        for y in (x, x * (1 + 1e-13), np.where(rng.random(x.size) < 0.5, 0.0, x)):
            want = C.numpy_checks(st, rnd, y, free, upper)
            assert not want.all()  # some rows fail: the verdicts say something
            for batch in (1, 3, 1 << 16):
                monkeypatch.setattr(certify_compiled, "CHECK_BATCH", batch)
                got = certify_compiled.compiled_checks(st, rnd, y, free, upper)
                assert got is not None and np.array_equal(got, want), batch
