"""sensed-78: the sweeps' gate (``solvers/sweep_gate.py``) reads a block's largest
connected piece before it searches the block's depth, and decides as before.

The expected pieces come from a union-find written here over the hand-built blocks'
successor lists (not SciPy's components); the expected decisions from the gate's
documented rule (its module docs) evaluated here from the depth searched by
:func:`~mitld_lp.solvers.jump_cost.block_depth` on the same block."""

from __future__ import annotations

import pytest

from mitld_lp.solvers import jump_cost, sweep_gate
from tests.test_sweep_gate_choice import _block, _grid, _shallow


def _pieces(succ: list[list[int]]) -> list[int]:
    """The sizes of the weakly connected pieces of ``succ`` (a union-find)."""
    parent = list(range(len(succ)))

    def root(s: int) -> int:
        while parent[s] != s:
            parent[s] = parent[parent[s]]
            s = parent[s]
        return s

    for s, ts in enumerate(succ):
        for t in ts:
            parent[root(s)] = root(t)
    sizes: dict[int, int] = {}
    for s in range(len(succ)):
        sizes[root(s)] = sizes.get(root(s), 0) + 1
    return sorted(sizes.values())


def _rings(sizes: list[int], chord: bool = False) -> list[list[int]]:
    """Disjoint directed rings of ``sizes`` states (``chord``: each state also moves two
    ahead), numbered one ring after the other."""
    out: list[list[int]] = []
    for n in sizes:
        base = len(out)
        out += [[base + (s + 1) % n] + ([base + (s + 2) % n] if chord and n > 2 else [])
                for s in range(n)]
    return out


def _rule(block, loaded: bool) -> bool:
    """The gate's documented rule, from the searched depth: compiled where the block is
    deeper than the NumPy sweeps carry and its compiled forecast is the smaller."""
    f = sweep_gate.forecast(block, loaded)
    return f.depth > sweep_gate.JACOBI_SWEEPS and f.compiled < f.numpy


@pytest.mark.parametrize("succ", [
    _rings([16] * 154),  # the sensed case's blocks: 154 pieces of at most 16 states
    _rings([3, 101, 7, 102, 1], chord=True),
    _rings([40, 250]),
    _grid(30, 20),
    _shallow(3000, 3, 7),
])
def test_largest_part_is_the_largest_piece(succ: list[list[int]]) -> None:
    assert sweep_gate.largest_part(_block(succ)) == _pieces(succ)[-1]


def test_largest_part_of_an_empty_block() -> None:
    assert sweep_gate.largest_part(_block([])) == 0


@pytest.mark.parametrize("succ", [
    _rings([16] * 154),  # many shallow pieces: decided without a search
    _rings([101] * 30),  # each piece's depth at most 100: without a search
    _rings([102] * 30),  # a ring of 102 states: depth 51 (undirected), searched
    _rings([5] * 400 + [1200]),  # one deep piece among shallow ones: searched
    _grid(128, 64),
    _shallow(8192, 4, 1),
])
@pytest.mark.parametrize("loaded", [False, True])
def test_same_decision_as_the_searched_depth(succ: list[list[int]], loaded: bool,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    block = _block(succ)
    expected = _rule(block, loaded)
    searched = []
    depth = jump_cost.block_depth

    def counted(b):
        searched.append(b)
        return depth(b)

    monkeypatch.setattr(jump_cost, "block_depth", counted)
    assert sweep_gate.prefers_compiled(block, loaded) is expected
    if _pieces(succ)[-1] <= sweep_gate.JACOBI_SWEEPS + 1:
        assert not searched  # no piece deep enough: no search
