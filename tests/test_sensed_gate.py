"""sensed-78: the sweeps' gate (``solvers/sweep_gate.py``) reads a block's largest
connected piece before it searches the block's depth, and decides as before.

The expected pieces come from a union-find written here over the hand-built blocks'
successor lists (not SciPy's components); the expected decisions from the gate's
documented rule (its module docs) evaluated here from the depth searched by
:func:`~mitld_lp.solvers.jump_cost.block_depth` on the same block."""

from __future__ import annotations

import pytest

from mitld_lp.solvers import jump_cost, sweep_gate
from tests.test_sweep_gate_choice import gate_block, gate_grid, shallow_gate_block


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


def _rings(sizes: list[int], steps: int = 1) -> list[list[int]]:
    """Disjoint directed rings of ``sizes`` states, each state moving 1 to ``steps``
    ahead (fewer in a ring too small), numbered one ring after the other."""
    out: list[list[int]] = []
    for n in sizes:
        base = len(out)
        out += [sorted({base + (s + k) % n for k in range(1, min(steps, n - 1) + 1)})
                or [base + s] for s in range(n)]
    return out


def _rule(block, loaded: bool) -> bool:
    """The gate's documented rule, from the searched depth: compiled where the block is
    deeper than the NumPy sweeps carry and its compiled forecast is the smaller."""
    f = sweep_gate.forecast(block, loaded)
    return f.depth > sweep_gate.JACOBI_SWEEPS and f.compiled < f.numpy


@pytest.mark.parametrize("succ", [
    _rings([16] * 154),  # the sensed case's blocks: 154 pieces of at most 16 states
    _rings([3, 101, 7, 102, 1], steps=2),
    _rings([40, 250]),
    gate_grid(30, 20),
    shallow_gate_block(3000, 3, 7),
])
def test_largest_part_is_the_largest_piece(succ: list[list[int]]) -> None:
    assert sweep_gate.largest_part(gate_block(succ)) == _pieces(succ)[-1]


def test_largest_part_of_an_empty_block() -> None:
    assert sweep_gate.largest_part(gate_block([])) == 0


@pytest.mark.parametrize("succ", [
    _rings([16] * 154),  # many shallow pieces: decided without a search
    _rings([101] * 30),  # each piece's depth at most 100: without a search
    _rings([102] * 30),  # a ring of 102 states: depth 51 (undirected), searched
    _rings([5] * 400 + [1200]),  # one deep piece among shallow ones: searched
    gate_grid(128, 64),
    shallow_gate_block(8192, 4, 1),
])
@pytest.mark.parametrize("loaded", [False, True])
def test_same_decision_as_the_searched_depth(succ: list[list[int]], loaded: bool,
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    block = gate_block(succ)
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


def _four_rule(block, loaded: bool, paid: bool, cheap: bool) -> bool:
    """The two-model rule as documented (``prefers_four``), written out from the searched
    depth: NumPy ``3 min(d, 100)`` sweeps (the jump's rounds past 100 steps), compiled
    ``1 + d`` sweeps plus the load (none loaded, 2e5 with the loader's run-time set up,
    else 2.3e6 from a warm cache or numba's 5e7)."""
    d = jump_cost.block_depth(block)
    n, nnz = int(block.states.size), float(block.inner.nnz)
    sweep = nnz + float(block.choices.shape[0])
    numpy = 3.0 * min(d, 100) * sweep
    if d > 100:
        numpy += (1 + d / jump_cost.LOOK_AHEAD) * (jump_cost.ROUND_STATE * n
                                                    + jump_cost.ROUND_ENTRY * nnz)
    load = 0.0 if loaded else 2.0e5 if paid else 2.3e6 if cheap else 5.0e7
    return load + (1.0 + d) * sweep < numpy


FOUR_BLOCKS = [
    _rings([16] * 154, steps=2),  # the sensed case's pieces: 154 of 16 states
    _rings([40] * 154, steps=3),
    _rings([16] * 20),
    _rings([3] * 50),  # too small for any load but none
    gate_grid(30, 20),
    gate_grid(128, 64),  # deeper than the NumPy sweeps carry
    shallow_gate_block(3000, 3, 7),
    _rings([5] * 400 + [1200]),
]


@pytest.mark.parametrize("succ", FOUR_BLOCKS)
@pytest.mark.parametrize(("loaded", "paid", "cheap"), [
    (True, True, True), (False, True, True), (False, False, True), (False, False, False)])
def test_two_models_follow_their_forecast(succ: list[list[int]], loaded: bool, paid: bool,
                                          cheap: bool, monkeypatch: pytest.MonkeyPatch
                                          ) -> None:
    from mitld_lp.util import kernel_loader

    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: paid)
    monkeypatch.setattr(sweep_gate, "_CHEAP", [cheap])
    block = gate_block(succ)
    assert sweep_gate.prefers_four(block, loaded) is _four_rule(block, loaded, paid, cheap)


def test_a_shallow_block_of_two_models_goes_compiled_of_one_model_not(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """154 pieces of 40 states, each moving 1-3 ahead (depth 7, about the sensed case's
    blocks' entries a state): one model's rule never sends it compiled (no piece deeper
    than the NumPy sweeps carry); two models' does once the kernel is loaded, and with
    the loader's run-time set up; the size floors hold for both."""
    from mitld_lp.solvers import kernels
    from mitld_lp.util import kernel_loader

    block = gate_block(_rings([40] * 154, steps=3))
    assert jump_cost.block_depth(block) == 7  # ceil(20 / 3)
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    monkeypatch.setattr(kernels, "compiled_kernel", lambda: object())
    for loaded in (False, True):
        monkeypatch.setattr(kernels, "kernel_loaded", lambda loaded=loaded: loaded)
        assert not sweep_gate.use_compiled(10**7, block.inner.nnz, block, 2)
        assert sweep_gate.use_compiled(10**7, block.inner.nnz, block, 4)
        assert not sweep_gate.use_compiled(kernels.COMPILED_MIN_ENTRIES - 1,
                                           block.inner.nnz, block, 4)
        assert not sweep_gate.use_compiled(10**7, block.inner.nnz, None, 4)
    monkeypatch.setattr(kernels, "compiled_kernel", lambda: None)  # numba missing
    assert not sweep_gate.use_compiled(10**7, block.inner.nnz, block, 4)
