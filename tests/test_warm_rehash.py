"""``mitld-lp warm`` compiles the explorer's ``rehash`` too (mitld_lp.worlds.prism_explore):
a build past its first table calls it, and a first load after ``warm`` compiled it (1 s of
CPU, 120 MB more) where it was left out."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stormpy")

import stormpy  # noqa: E402

from mitld_lp.util import kernel_loader  # noqa: E402
from mitld_lp.worlds import prism_explore  # noqa: E402


def _signature(args: tuple) -> tuple:
    """What numba compiles a call for: each array's dtype and rank, each scalar's type."""
    return tuple((a.dtype.str, a.ndim, a.flags.c_contiguous) if isinstance(a, np.ndarray)
                 else type(a) for a in args)


class _Recording:
    """The kernels module, with the arguments of every ``rehash`` call kept."""

    def __init__(self, real, calls: list) -> None:
        self._real, self._calls = real, calls

    def __getattr__(self, name: str):
        return getattr(self._real, name)

    def rehash(self, *args):
        self._calls.append(_signature(args))
        return self._real.rehash(*args)


def _program(tmp_path):
    path = tmp_path / "warm.prism"
    path.write_text(prism_explore.WARM_PROGRAM, encoding="ascii")
    return prism_explore.compile_program(stormpy.parse_prism_program(str(path)), None)


def test_warm_compiles_rehash_as_a_growing_build_calls_it(monkeypatch, tmp_path):
    real = prism_explore._kernels()
    calls: list = []
    monkeypatch.setattr(prism_explore, "_kernels", lambda: _Recording(real, calls))
    monkeypatch.setattr(prism_explore, "kernel_ready", lambda: False)  # as if cold
    assert prism_explore.compile_kernels(stormpy)
    assert len(calls) == 1  # warm called it once
    warm = calls.pop()
    compiled = _program(tmp_path)
    grown = prism_explore.explore_program(compiled, 100, guess=1)  # 4 slots: must grow
    assert not isinstance(grown, str)
    assert calls and all(c == warm for c in calls)  # the very signature warm compiled
    # the grown build is the plain one: x in 0..2 and b both ways, 6 states (by hand)
    plain = prism_explore.explore_program(compiled, 100)
    assert not isinstance(plain, str)
    assert len(grown.values) == 6
    assert {tuple(r) for r in grown.values.tolist()} == {tuple(r) for r in plain.values.tolist()}


def test_kernel_ready_asks_for_rehash(monkeypatch):
    asked: list = []

    def cached(module, name):
        asked.append(name)
        return name != "rehash"

    monkeypatch.setattr(kernel_loader, "module_cached", cached)
    assert not prism_explore.kernel_ready()  # explore and label_flags alone: not ready
    assert "rehash" in asked
