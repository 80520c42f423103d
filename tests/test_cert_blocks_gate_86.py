"""cert-86: the chain's blocks' compiled path asks the loader's cache, as its sibling
gates do (:func:`mitld_lp.solvers.certify_blocks.blocks_cached`).

With the load paid but the kernel not in the cache, the blocks come from NumPy
(``compiled_chain_blocks`` gives None: no compile in a certificate); with it cached,
the compiled blocks equal :func:`mitld_lp.solvers.graph.blocks_from`'s, array for
array; the cache is asked once a process, whatever the calls after."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from mitld_lp.solvers import certify_blocks as CB
from mitld_lp.solvers import certify_compiled as CC
from mitld_lp.solvers.graph import blocks_from


def _loader(monkeypatch, cached: bool) -> list:
    """A loader whose load is paid and whose cache holds the kernel or not; the cache's
    look-ups recorded."""
    asked: list = []

    def module_cached(*kernel):
        asked.append(kernel)
        return cached

    fake = SimpleNamespace(compiled_paid=lambda: True, module_cached=module_cached,
                           prepare=lambda: None)
    monkeypatch.setattr(CC, "kernel_loader", fake)
    monkeypatch.setattr(CC, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(CB, "_BLOCKS_WARM", [])  # a fresh process's
    return asked


def _ids():
    rng = np.random.default_rng(86_001)
    comp = rng.integers(0, 300, size=1000).astype(np.int32)
    level = rng.integers(0, 9, size=300).astype(np.int32)
    return comp, level


def test_a_kernel_not_cached_leaves_the_blocks_to_numpy(monkeypatch) -> None:
    asked = _loader(monkeypatch, cached=False)
    comp, level = _ids()
    assert CB.compiled_chain_blocks(comp, level, np.zeros(comp.size)) is None
    assert CB.compiled_chain_blocks(comp, level, np.zeros(comp.size)) is None
    assert asked == [CB.BLOCKS_KERNEL]  # asked once, the kernel the gate runs
    assert CB.BLOCKS_KERNEL == ("mitld_lp.solvers.certify_kernels", "chain_blocks")


def test_a_cached_kernel_gives_the_numpy_blocks(monkeypatch) -> None:
    asked = _loader(monkeypatch, cached=True)
    comp, level = _ids()
    diag = np.random.default_rng(3).random(comp.size)
    for _ in range(2):
        got = CB.compiled_chain_blocks(comp, level, diag)
        assert got is not None
        want = blocks_from(comp, level, diag)
        for name in ("component", "level", "size", "by_level", "level_starts",
                     "self_loop"):
            assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert len(asked) == 1


def test_the_real_loader_is_asked_about_a_real_kernel() -> None:
    """The kernel the gate names is one the certificate's kernel module defines and the
    warm command compiles (so a warmed cache answers True)."""
    from mitld_lp.solvers import certify_kernels
    from mitld_lp.util.warm_kernels import SIGNATURES

    module, name = CB.BLOCKS_KERNEL
    assert module == certify_kernels.__name__ and hasattr(certify_kernels, name)
    assert SIGNATURES[module][name]  # warmed with at least one signature
