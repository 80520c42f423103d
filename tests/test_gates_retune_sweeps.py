"""gates-retune: the iteration's sweep gate (:mod:`mitld_lp.solvers.sweep_gate`) counts
the kernel loader's warm load (0.020 s: 2.3e6 compiled entries at 8.6 ns) where the
Gauss--Seidel kernel's cache file is there and the loader is on, numba's 0.44 s (5e7)
otherwise; its decisions on grids of known depth against the forecast written here."""

from __future__ import annotations

import sys

import pytest

import mitld_lp.solvers
from mitld_lp.solvers import jump_cost, sweep_gate
from mitld_lp.util import kernel_loader
from tests.test_sweep_gate_choice import gate_block, gate_grid


def expected(w: int, h: int, loaded: bool, warm: bool) -> bool:
    """A ``w x h`` grid block, one choice a state: ``w*h`` states, ``4wh - 2w - 2h``
    inner entries, depth ``w + h - 2``; NumPy's forecast ``3 min(d, 100)`` sweeps plus
    the jump's rounds past 100 steps, the compiled one ``16 + d`` sweeps plus the load."""
    n, nnz, d = w * h, 4 * w * h - 2 * w - 2 * h, w + h - 2
    sweep = nnz + n
    numpy = 3.0 * min(d, 100) * sweep
    if d > 100:
        numpy += (1 + d / jump_cost.LOOK_AHEAD) * (jump_cost.ROUND_STATE * n
                                                    + jump_cost.ROUND_ENTRY * nnz)
    load = 0.0 if loaded else 2.3e6 if warm else 5.0e7
    return n > 100 and d > 100 and load + (16 + d) * sweep < numpy


GRIDS = [(64, 32), (64, 64), (96, 40), (128, 64), (60, 50), (200, 8), (40, 40)]


@pytest.mark.parametrize("wh", GRIDS)
@pytest.mark.parametrize("warm", [True, False])
@pytest.mark.parametrize("loaded", [True, False])
def test_the_gate_follows_the_forecast(wh: tuple[int, int], warm: bool, loaded: bool,
                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(sweep_gate, "_CHEAP", [warm])
    assert sweep_gate.prefers_compiled(gate_block(gate_grid(*wh)), loaded=loaded) == expected(
        *wh, loaded, warm)


def test_a_warm_load_sends_bus_n64s_second_block_compiled(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The 64 x 64 grid (depth 126, as bus n64 d3's second block): NumPy's forecast is
    below numba's import but above the loader's link."""
    middle = gate_block(gate_grid(64, 64))
    monkeypatch.setattr(sweep_gate, "_CHEAP", [False])
    assert not sweep_gate.prefers_compiled(middle, loaded=False)
    monkeypatch.setattr(sweep_gate, "_CHEAP", [True])
    assert sweep_gate.prefers_compiled(middle, loaded=False)


@pytest.mark.parametrize("why", ["off", "cold", "no numba"])
def test_the_load_is_numbas_unless_the_loader_links_a_cached_kernel(
        why: str, monkeypatch: pytest.MonkeyPatch) -> None:
    from mitld_lp.solvers import compiled_kernels

    monkeypatch.setattr(sweep_gate, "_CHEAP", [])
    if why == "off":
        monkeypatch.setattr(kernel_loader, "ENABLED", False)
    elif why == "cold":
        monkeypatch.setattr(kernel_loader, "cached", lambda f, q: False)
    else:
        monkeypatch.setitem(sys.modules, "mitld_lp.solvers.compiled_kernels", None)
        monkeypatch.delattr(mitld_lp.solvers, "compiled_kernels", raising=False)
    assert sweep_gate.load_is_cheap() is False
    # the same lookup with the loader on, numba there and the file cached: cheap
    monkeypatch.setattr(sweep_gate, "_CHEAP", [])
    monkeypatch.setattr(kernel_loader, "ENABLED", True)
    monkeypatch.setattr(kernel_loader, "cached", lambda f, q: q == "gauss_seidel")
    monkeypatch.setitem(sys.modules, "mitld_lp.solvers.compiled_kernels", compiled_kernels)
    assert sweep_gate.load_is_cheap() is True
