"""numba's gate and its load: which blocks are swept compiled (decided from the sizes
alone, before any work), a solve kept on NumPy never imports numba and brackets its
closed-form value, and a kernel loaded from the cache leaves PyYAML, cffi and its C
parser out of the process (numba_narrow) with the same bits and a later compile
working."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import analysis, kernels

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["MITLD_LP_KERNEL_LOADER"] = "0"  # numba's own load of its cache (kernel_loader)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _run(code: str, cwd: Path = ROOT) -> dict:
    done = subprocess.run([sys.executable, "-c", code], cwd=cwd, env=_env(),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _ring(n: int, skip: int) -> tuple[sp.csr_array, np.ndarray]:
    """n states, one choice each, to ``s + 1`` and ``s + skip`` (mod n): one strongly
    connected component of ``2 n`` entries (``skip`` 0: a self-loop, still inside)."""
    s = np.arange(n)
    rows = np.repeat(s, 2)
    cols = np.column_stack([(s + 1) % n, (s + skip) % n]).ravel()
    m = sp.csr_array((np.full(2 * n, 0.5), (rows, cols)), shape=(n, n))
    return m, np.arange(n + 1)


def test_the_analysis_guess_counts_the_entries_inside_a_component() -> None:
    need = kernels.COMPILED_MIN_BLOCK_ENTRIES
    assert kernels.COMPILED_MIN_ENTRIES <= need  # a block's product is at least the block
    n = need // 2  # 2 n entries, all inside the ring's one component
    m, groups = _ring(n, 2)
    assert m.nnz == need
    assert analysis._sweeps_compiled(m, groups, np.zeros(n, dtype=np.int64))
    m, groups = _ring(n - 1, 2)  # two entries short
    assert not analysis._sweeps_compiled(m, groups, np.zeros(n - 1, dtype=np.int64))
    # the same entries split into two components: neither is large enough
    m, groups = _ring(n, 2)
    halves = (np.arange(n) >= n // 2).astype(np.int64)
    assert not analysis._sweeps_compiled(m, groups, halves)
    # a chain (every state its own component) of as many entries: none inside any
    s = np.arange(n)
    chain = sp.csr_array((np.full(2 * n, 0.5), (np.repeat(s, 2),
                                                np.minimum(np.repeat(s, 2) + [1, 2] * n,
                                                           n - 1))), shape=(n, n))
    assert not analysis._sweeps_compiled(chain, groups, s)


def test_use_compiled_needs_both_sizes() -> None:
    lo_p, lo_b = kernels.COMPILED_MIN_ENTRIES, kernels.COMPILED_MIN_BLOCK_ENTRIES
    assert not kernels.use_compiled(lo_p - 1, lo_b)
    assert not kernels.use_compiled(10 * lo_p, lo_b - 1)
    if kernels.compiled_kernel() is not None:
        assert kernels.use_compiled(lo_p, lo_b)


#: Gambler's ruin as an MDP: states 0..N, 0 loses and N wins (both absorbing), every
#: other state bets with a fair-ish coin (up 0.45) or a worse one (up 0.40).  Pmax of
#: reaching N from i is the better coin's closed form (1 - r^i) / (1 - r^N), r = q/p.
#: The states 1..N-1 are one block of ~4N entries: the gate keeps it on NumPy.
RUIN = r"""
import json, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.mdp import MDP
from mitld_lp.solvers import interval_iteration
N, start = 400, 390
rows, cols, vals, groups, actions = [], [], [], [0], []
choice = 0
for s in range(N + 1):
    coins = [1.0] if s in (0, N) else [0.45, 0.40]
    for a, p in enumerate(coins):
        if s in (0, N):
            rows.append(choice); cols.append(s); vals.append(1.0)
        else:
            rows += [choice, choice]; cols += [s + 1, s - 1]; vals += [p, 1.0 - p]
        actions.append(a); choice += 1
    groups.append(choice)
m = sp.csr_array((vals, (rows, cols)), shape=(choice, N + 1))
target = np.zeros(N + 1, dtype=bool); target[N] = True
sink = np.zeros(N + 1, dtype=bool); sink[0] = True
mdp = MDP(matrix=m, row_groups=np.array(groups), choice_actions=np.array(actions, np.int32),
          action_names=(), initial=start, target=target, sink=sink,
          truncated=np.zeros(N + 1, dtype=bool), states=range(N + 1))
r = interval_iteration(mdp, target, progress=False, tol=1e-9, precision=None)
print(json.dumps({"lower": float(r.lower[start]), "upper": float(r.upper[start]),
                  "status": r.status.value, "numba": "numba" in sys.modules}))
"""


def test_a_solve_kept_on_numpy_never_imports_numba_and_brackets_the_closed_form() -> None:
    got = _run(RUIN)
    assert got["numba"] is False
    r, n, i = 0.55 / 0.45, 400, 390
    exact = (1.0 - r**i) / (1.0 - r**n)  # about 0.134
    assert got["lower"] <= exact <= got["upper"]
    assert got["upper"] - got["lower"] <= 1e-9


#: A kernel's first call after numba_narrow.import_numba; then a function compiled afresh
#: (a cache miss: the typing and target registries the load left out are installed then).
NARROW = r"""
import json, sys
import numpy as np, scipy.sparse as sp
before = {m: m in sys.modules for m in ("yaml", "cffi", "pycparser")}
from mitld_lp.solvers import kernels
from mitld_lp.util import numba_narrow
numba = numba_narrow.import_numba()
after_import = "yaml" in sys.modules
inner = sp.csr_array(np.array([[0.0, 0.5], [0.5, 0.0]]))
prep = kernels.Prepared(inner, np.array([0, 1, 2]))
local = np.column_stack([np.zeros(2), np.ones(2)])
kernels.compiled_sweeps(prep, np.full((2, 2), 0.25), local, 1e-12, 1000)
loaded = {m: m in sys.modules for m in ("yaml", "cffi", "pycparser")}
@numba.njit(cache=False)
def fresh(x):
    return np.linalg.norm(x) + np.sum(x) + abs(complex(0.0, 1.0))
from numba.core import config
print(json.dumps({"before": before, "after_import": after_import, "loaded": loaded,
                  "narrow": numba_narrow.installed(), "bounds": local[0].tolist(),
                  "fresh": float(fresh(np.array([3.0, 4.0]))),
                  "lazy_yaml": callable(config.yaml.safe_load)}))
"""


def test_narrow_load_leaves_yaml_and_cffi_out_and_compiles_after() -> None:
    pytest.importorskip("numba")
    # the first run fills a cold cache (a fresh checkout): a compile refreshes numba's
    # typing context, which loads cffi; the second is the load from the cache
    _run(NARROW)
    got = _run(NARROW)
    assert got["narrow"] is True
    assert got["bounds"][0] <= 0.5 <= got["bounds"][1]  # x = 1/4 + x/2
    assert got["bounds"][1] - got["bounds"][0] <= 1e-12
    assert got["fresh"] == 3.0 + 4.0 + 5.0 + 1.0
    for mod, was in got["before"].items():
        if not was:
            assert got["loaded"][mod] is False, mod
    assert got["after_import"] is False or got["before"]["yaml"]
    assert got["lazy_yaml"] is True  # numba's config still reads a config file


def test_a_numba_config_file_keeps_yaml_loaded(tmp_path: Path) -> None:
    pytest.importorskip("numba")
    pytest.importorskip("yaml")
    (tmp_path / ".numba_config.yaml").write_text("debug_cache: 0\n", encoding="utf-8")
    code = ("import json, sys\nfrom mitld_lp.util import numba_narrow\n"
            "numba_narrow.import_numba()\n"
            "print(json.dumps({'yaml': 'yaml' in sys.modules}))")
    assert _run(code, cwd=tmp_path)["yaml"] is True


COMPILED_MODULES = ("mitld_lp.solvers.compiled_graph", "mitld_lp.solvers.level_kernels",
                    "mitld_lp.solvers.compiled_kernels", "mitld_lp.sensing.kernels",
                    "mitld_lp.sensing.group_kernels", "mitld_lp.sensing.fsum_kernels")


@pytest.mark.parametrize("module", COMPILED_MODULES)
def test_each_compiled_module_imports_numba_without_yaml(module: str,
                                                          tmp_path: Path) -> None:
    """Whichever compiled module imports numba first in a process, PyYAML stays out
    (no config file in the working directory), and numba's config can still read one."""
    pytest.importorskip("yaml")
    code = ("import importlib, json, sys\n"
            f"importlib.import_module({module!r})\n"
            "from mitld_lp.util import kernel_loader\n"
            "kernel_loader.numba_module()  # a lazy module's kernel's miss\n"
            "config = sys.modules['numba.core.config']\n"
            "print(json.dumps({'yaml': 'yaml' in sys.modules,"
            " 'lazy': callable(config.yaml.safe_load)}))")
    assert _run(code, cwd=tmp_path) == {"yaml": False, "lazy": True}
