"""gates-retune: the product loop's gate (:func:`mitld_lp.product.table_levels.
compiled_wanted`) with the kernel loader's cheap load (0.02 s, 3 MB through its ELF
linker) on a warm cache, and the old rule (0.04 s, 48 MiB, 2%) on a cold cache or with
the loader off; the decisions checked against the rule written here from its inputs,
and the product the same to the bit with the gate forced either way."""

from __future__ import annotations

import importlib.util
import os
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from mitld_lp.product import table_levels as tl
from mitld_lp.util import kernel_files, kernel_loader

HAS_NUMBA = importlib.util.find_spec("numba") is not None


def rule(n_world: int, expanded: int, queued: int, batches: int, per_state: float,
         warm: bool) -> bool:
    """The gate by hand: a warm load costs 0.02 s and 3 MiB, at most a fifth of the
    product still to come (96 bytes a state, 32 a transition); a cold one 0.04 s and
    48 MiB at most 2% of it.  It pays where NumPy's levels still to come (0.08 us a
    state, 75 us a batch of the queue's width once 32 batches were seen) cost twice
    the load, and never past half the world."""
    seconds, size, share = (0.02, 3 * 2**20, 0.2) if warm else (0.04, 48 * 2**20, 0.02)
    left = n_world - expanded
    if 2 * expanded >= n_world:
        return False
    if size > share * left * (96 + 32 * per_state):
        return False
    numpy_s = left * 0.08e-6
    if batches >= 32:
        numpy_s += left / max(queued, 1) * 75e-6
    return numpy_s >= 2 * seconds


# (world states, expanded, queued, batches, transitions a state), away from the borders
CASES = [
    (168_411, 20_000, 265, 100, 1.17),  # firewire_dl 3-600: thin levels
    (168_411, 20_000, 265, 10, 1.17),  # ... before the frontier's width is trusted
    (113_542, 5_000, 3_000, 40, 2.2),  # zeroconf_dl 1000-1: 0.005 + 0.009 s left < 0.04
    (608_085, 10_000, 20_000, 40, 1.8),  # csma 4-2: 0.048 s by its states alone
    (43_133, 1_000, 500, 40, 3.3),  # consensus 4-4: too small for 3 MiB at 20%
    (2_000_000, 0, 1, 0, 2.0),
    (20_000_000, 0, 1, 0, 2.0),
    (20_000_000, 4_000_000, 1, 0, 2.0),
    (20_000_000, 5_000_000, 1, 0, 2.0),
    (900_000, 0, 1, 0, 2.0),  # 0.072 s: pays 0.02 twice by its states, not 0.04
    (300_000, 10_000, 100, 40, 1.5),
    (20_000_000, 10_000_000, 1, 0, 2.0),  # half the world expanded
]


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("warm", [True, False])
def test_the_gate_follows_the_rule_on_a_warm_and_a_cold_cache(
        case: tuple, warm: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    n_world, expanded, queued, batches, per_state = case
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    monkeypatch.setattr(tl, "loop_cached", lambda: warm)
    lean = SimpleNamespace(table_steps=np.zeros(1), batches=batches)
    assert tl.compiled_wanted(lean, n_world, expanded, queued, per_state) == rule(
        n_world, expanded, queued, batches, per_state, warm)


def test_the_warm_rule_admits_what_the_cold_one_refused(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """firewire_dl's and csma's figures: loaded on a warm cache only; consensus never
    before its load is paid; everything once it is paid, nothing with the loop off."""
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    lean = SimpleNamespace(table_steps=np.zeros(1), batches=100)
    firewire, csma, consensus = CASES[0], CASES[3], CASES[4]
    for warm, expect in ((True, True), (False, False)):
        monkeypatch.setattr(tl, "loop_cached", lambda w=warm: w)
        assert tl.compiled_wanted(lean, *firewire[:3], firewire[4]) is expect
        assert tl.compiled_wanted(lean, *csma[:3], csma[4]) is expect
        assert not tl.compiled_wanted(lean, *consensus[:3], consensus[4])
    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: True)
    assert tl.compiled_wanted(lean, *consensus[:3], consensus[4])
    monkeypatch.setattr(tl, "COMPILED", False)
    assert not tl.compiled_wanted(lean, *firewire[:3], firewire[4])


def test_cached_sees_a_cache_file_and_refuses_with_the_loader_off(
        tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """:func:`kernel_loader.cached`: False in an empty cache directory, True once a file
    named as the loader names the kernel's (any signature) is there, False with the
    loader off or a ``NUMBA_*`` setting in force (numba's compile then)."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    py_file = str(tmp_path / "src" / "some_kernels.py")
    assert not kernel_loader.cached(py_file, "table_levels")
    (directory,) = kernel_files.directories(py_file)
    directory.mkdir(parents=True)
    # another kernel's file, and one whose name only starts with this one's
    (directory / ("some_kernels.other-0123" + kernel_files.SUFFIX)).write_bytes(b"x")
    (directory / ("some_kernels.table_levels_x-0123" + kernel_files.SUFFIX)).write_bytes(b"x")
    assert not kernel_loader.cached(py_file, "table_levels")
    name = kernel_files.file_name(py_file, "table_levels", (("int",),))
    (directory / name).write_bytes(b"x")
    assert kernel_loader.cached(py_file, "table_levels")
    monkeypatch.setattr(kernel_loader, "ENABLED", False)
    assert not kernel_loader.cached(py_file, "table_levels")
    monkeypatch.setattr(kernel_loader, "ENABLED", True)
    monkeypatch.setenv("NUMBA_OPT", "1")
    assert not kernel_loader.cached(py_file, "table_levels")


def test_a_cache_file_older_than_the_source_is_not_warm(
        tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A cache file written before the kernel module's source last changed (an upgrade
    or an edit: the load would refuse its key and compile) does not count as warm; the
    same file written after the source does.  The times are set by hand."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    source = tmp_path / "src" / "some_kernels.py"
    source.parent.mkdir()
    source.write_text("# a kernel module\n")
    (directory,) = kernel_files.directories(str(source))
    directory.mkdir(parents=True)
    cache = directory / kernel_files.file_name(str(source), "table_levels", (("int",),))
    cache.write_bytes(b"x")
    os.utime(source, ns=(2_000_000_000_000_000_000, 2_000_000_000_000_000_000))
    os.utime(cache, ns=(1_000_000_000_000_000_000, 1_000_000_000_000_000_000))
    assert not kernel_loader.cached(str(source), "table_levels")
    os.utime(cache, ns=(3_000_000_000_000_000_000, 3_000_000_000_000_000_000))
    assert kernel_loader.cached(str(source), "table_levels")


def test_no_numba_no_warm_load(monkeypatch: pytest.MonkeyPatch) -> None:
    """numba missing: the loop's module does not import, so the load is never taken as
    cheap (and :func:`~mitld_lp.product.table_levels.run_compiled` leaves the levels to
    NumPy)."""
    # the package the import statement reads (sys.modules'), not an attribute of
    # ``mitld_lp``: a test that re-imports the package leaves the two apart
    package = importlib.import_module("mitld_lp.product")
    monkeypatch.setitem(sys.modules, "mitld_lp.product.bfs_kernels", None)
    monkeypatch.delattr(package, "bfs_kernels", raising=False)
    monkeypatch.setattr(tl, "_CACHED", [])
    assert tl.loop_cached() is False
    assert tl.run_compiled(None, SimpleNamespace(index=SimpleNamespace(
        dense=np.zeros(1), dense_limit=10)), 0, None, 1) is None


@pytest.mark.skipif(not HAS_NUMBA, reason="needs numba")
@pytest.mark.parametrize("spec", ["F goal", "G (goal -> F[0,9] goal)"])
def test_the_product_is_the_same_with_the_gate_forced_either_way(
        spec: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """The same product to the bit whether the gate sends every level after the first
    to the compiled loop or none."""
    from tests.test_product_bfs_buffers import Chain, assert_same, task

    world, sta = Chain(3000, 2500, goal_every=97), task(spec)
    from mitld_lp.product import product

    monkeypatch.setattr(kernel_loader, "compiled_paid", lambda: False)
    calls: list[int] = []
    real = tl.run_compiled

    def counted(*a):
        calls.append(1)
        return real(*a)

    from mitld_lp.product import build
    monkeypatch.setattr(build, "run_compiled", counted)
    products = []
    for forced in (True, False):
        monkeypatch.setattr(build, "compiled_wanted", lambda *a, f=forced, **k: f)
        calls.clear()
        products.append(product(world, sta, max_states=10**6))
        assert bool(calls) is forced
    assert_same(*products)
