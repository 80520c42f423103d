"""sensing/rows.Lookup: the frontier build's cached tables of values by pairs of small
integers, checked against the function that makes them, called directly."""

from __future__ import annotations

import numpy as np

from mitld_lp.sensing import rows
from mitld_lp.sensing.rows import Lookup


def test_lookup_gives_each_pair_its_value_made_once(monkeypatch) -> None:
    """Rows of pairs whose box grows batch by batch (the dense copy regrown, then too
    large for it: the dict alone) get ``make(a, b)`` each, made once per pair."""
    monkeypatch.setattr(rows, "DENSE", 1 << 12)  # a small box: the dict path is met
    calls: list[tuple[int, int]] = []

    def make(a: int, b: int) -> int:
        calls.append((a, b))
        return (7 * a + 3 * b) % 11 - 1  # values >= -1, -1 included

    look = Lookup(make)
    rng = np.random.default_rng(3)
    for hi in (5, 9, 30, 40, 70, 200, 5):
        a = rng.integers(0, hi, 500)
        b = rng.integers(0, 1 + hi // 3, 500)
        want = [(7 * x + 3 * y) % 11 - 1 for x, y in zip(a.tolist(), b.tolist(), strict=True)]
        assert look(a, b).tolist() == want
    assert len(calls) == len(set(calls))  # each pair made once
    assert look(np.zeros(0, np.int64), np.zeros(0, np.int64)).tolist() == []
