"""A kernel whose callee in another module changed: numba's disk cache checks the
caller's own file only, so it would run the old callee; the loader flushes numba's
index of such a kernel before numba's call (mitld_lp.util.kernel_sources)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.util import kernel_loader, kernel_sources

pytest.importorskip("numba")

CALLER = textwrap.dedent("""
    import numba
    from callee import g

    @numba.njit(cache=True)
    def f(x):
        return g(x) + 1
""")
CALLEE = "import numba\n\n@numba.njit(cache=True)\ndef g(x):\n    return x * {k}\n"
RUN = textwrap.dedent("""
    import sys, types
    import caller
    from mitld_lp.util import kernel_sources
    if sys.argv[1] == "flush":
        kernel_sources.STALE.add((caller.f.py_func.__module__, caller.f.py_func.__qualname__))
        kernel = types.SimpleNamespace(__module__=caller.f.py_func.__module__,
                                       __qualname__=caller.f.py_func.__qualname__)
        kernel_sources.flush_numba_cache(kernel, caller.f)
        assert not kernel_sources.STALE
    print(caller.f(10))
""")


def _run(folder: Path, how: str) -> int:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(folder / "cache"),
           "PYTHONPATH": os.pathsep.join([str(folder), str(Path(__file__).parents[1])])}
    out = subprocess.run([sys.executable, "-c", RUN, how], cwd=folder, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return int(out.stdout.split()[-1])


def test_numba_keeps_a_stale_callee_and_the_flush_compiles_afresh(tmp_path):
    (tmp_path / "caller.py").write_text(CALLER)
    (tmp_path / "callee.py").write_text(CALLEE.format(k=2))
    assert _run(tmp_path, "plain") == 21  # 10 * 2 + 1, compiled and cached
    (tmp_path / "callee.py").write_text(CALLEE.format(k=3))  # the caller's file unchanged
    # numba's own cache: the caller's old machine code, with the old callee inside
    assert _run(tmp_path, "plain") == 21
    assert _run(tmp_path, "flush") == 31  # 10 * 3 + 1 once its index is flushed
    assert _run(tmp_path, "plain") == 31  # and saved so


def test_a_stale_kernel_is_flushed_once_before_numbas_call(monkeypatch, tmp_path):
    order = []

    class Cache:
        _cache_path = str(tmp_path)  # the lock file goes there

        def flush(self) -> None:
            order.append("flush")

    class Dispatcher:
        _cache = Cache()

        def recompile(self) -> None:
            order.append("recompile")

        def __call__(self, *args):
            order.append("call")
            return 7

    def twice(x):
        return 2 * x

    kernel = kernel_loader.Kernel(twice, {"cache": True})
    monkeypatch.setattr(kernel_loader, "_load", lambda k, key: None)
    monkeypatch.setattr(kernel_loader, "_store", lambda *a: None)
    monkeypatch.setattr(kernel, "numba_dispatcher", lambda: Dispatcher())
    kernel_sources.STALE.add((twice.__module__, twice.__qualname__))
    assert kernel(3) == 7
    assert order == ["recompile", "call"]
    assert (twice.__module__, twice.__qualname__) not in kernel_sources.STALE
    kernel._calls.clear()
    assert kernel(3) == 7
    assert order == ["recompile", "call", "call"]  # not stale any more: once


def _module(monkeypatch, name: str, **values) -> None:
    import types

    module = types.ModuleType(name)
    module.__dict__.update(values)
    monkeypatch.setitem(sys.modules, name, module)


def _kernel_of(module: str, name: str) -> kernel_loader.Kernel:
    def body(x):
        return x

    body.__module__, body.__qualname__ = module, name
    return kernel_loader.Kernel(body, {"cache": True})


def test_kernel_modules_follow_the_kernels_in_globals_transitively(monkeypatch):
    asked = []

    class Lazy:  # a lazy numba: any attribute asked would import numba
        def __getattr__(self, name):
            asked.append(name)
            raise AssertionError(name)

    _module(monkeypatch, "mitld_lp._stale_a", numba=Lazy(), g=_kernel_of("mitld_lp._stale_b", "g"),
            own=_kernel_of("mitld_lp._stale_a", "own"), np=np,
            outside=_kernel_of("elsewhere", "h"))
    _module(monkeypatch, "mitld_lp._stale_b", numba=Lazy(), k=_kernel_of("mitld_lp._stale_c", "k"))
    _module(monkeypatch, "mitld_lp._stale_c", back=_kernel_of("mitld_lp._stale_a", "own"))
    found = kernel_sources.kernel_modules("mitld_lp._stale_a")
    assert found == {"mitld_lp._stale_b", "mitld_lp._stale_c"}  # c through b; not a, not elsewhere
    assert asked == []
    assert kernel_sources.kernel_modules("mitld_lp._stale_c") == {"mitld_lp._stale_a",
                                                                  "mitld_lp._stale_b"}


def test_the_sweeps_kernel_names_the_modules_it_imports_kernels_from():
    """compiled_kernels' sweeps call the one- and two-model sweeps inlined: numba names
    no environment of theirs, so only the imports say that an edit of theirs is the
    sweeps' too.  Expected: the modules its source imports names from (read by ast)."""
    import ast

    from mitld_lp.solvers import compiled_kernels

    tree = ast.parse(Path(compiled_kernels.__file__).read_text())
    imported = {node.module for node in tree.body if isinstance(node, ast.ImportFrom)
                and node.module and node.module.startswith("mitld_lp.solvers.")}
    assert imported  # the test reads something
    assert imported <= kernel_sources.kernel_modules("mitld_lp.solvers.compiled_kernels")
