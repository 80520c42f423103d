"""The kernel loader (mitld_lp.util.kernel_loader): a kernel linked from its cache
file gives numba's arrays to the bit, a damaged, foreign or half-written file is left to
numba and written again, and a process whose cache is warm never imports numba."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

pytest.importorskip("numba")

from mitld_lp.solvers import compiled_graph
from mitld_lp.util import kernel_loader  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(
    any(k.startswith("NUMBA_") and k != "NUMBA_CACHE_DIR" for k in os.environ),
    reason="a NUMBA_* setting leaves every kernel to numba")


def _graph(rng: np.random.Generator, n: int, p: float) -> tuple[np.ndarray, np.ndarray]:
    dense = rng.random((n, n)) < p
    g = sp.csr_array(dense.astype(np.int8))
    return g.indptr.astype(np.int64), g.indices.astype(np.int64)


def _mdp(rng: np.random.Generator, n: int) -> tuple:
    """A random choice matrix: 1-3 choices a state, 1-3 successors a choice."""
    counts = rng.integers(1, 4, size=n)
    row_groups = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rows = []
    for _ in range(int(row_groups[-1])):
        succ = rng.choice(n, size=int(rng.integers(1, 4)), replace=False)
        row = np.zeros(n)
        row[succ] = 1.0 / succ.size
        rows.append(row)
    m = sp.csr_array(np.array(rows))
    return m, row_groups


def _linked(kernel: kernel_loader.Kernel, args: tuple):
    """The kernel's call linked from its cache file (written first by numba's call)."""
    key = kernel_loader.type_key(args)
    assert key is not None
    kernel(*args)  # a miss writes the file; a hit links it
    kernel._calls.pop(key, None)  # a miss's numba dispatcher: read the file now
    call = kernel_loader._load(kernel, key)
    assert call is not None, "the cache file was not written or not linked"
    return call


def test_strong_components_loaded_equal_numba_and_scipy() -> None:
    rng = np.random.default_rng(7)
    kernel = compiled_graph.strong_components
    assert isinstance(kernel, kernel_loader.Kernel)
    for n, p in [(1, 0.5), (30, 0.05), (200, 0.01), (400, 0.004)]:
        ptr, succ = _graph(rng, n, p)
        for descending in (np.bool_(False), np.bool_(True)):
            args = (ptr, succ, descending)
            loaded = _linked(kernel, args)(*args)
            numba_says = kernel.numba_dispatcher()(*args)
            assert loaded[0] == numba_says[0]
            np.testing.assert_array_equal(loaded[1], numba_says[1])
            assert loaded[1].dtype == numba_says[1].dtype
            # an independent route: SciPy's strong components, the same partition
            graph = sp.csr_array((np.ones(succ.size), succ, ptr), shape=(n, n))
            n_scipy, lab = connected_components(graph, connection="strong")
            assert loaded[0] == n_scipy
            pairs = set(zip(loaded[1].tolist(), lab.tolist(), strict=True))
            assert len(pairs) == n_scipy  # a bijection between the two numberings


def test_end_components_loaded_equal_numba_and_brute_force() -> None:
    rng = np.random.default_rng(11)
    kernel = compiled_graph.end_components_among
    for n in (5, 40, 150):
        m, row_groups = _mdp(rng, n)
        cand = np.sort(rng.choice(n, size=max(1, n * 2 // 3), replace=False)).astype(np.int64)
        args = (m.indptr, m.indices, m.data > 0, row_groups, cand)
        alive, allowed, label = _linked(kernel, args)(*args)
        n_alive, n_allowed, n_label = kernel.numba_dispatcher()(*args)
        np.testing.assert_array_equal(alive, n_alive)
        np.testing.assert_array_equal(allowed, n_allowed)
        np.testing.assert_array_equal(label, n_label)
        # brute force: a state is in an end component among cand iff a fixed point of
        # "keep the choices staying in the surviving set and in one strong component"
        keep = np.zeros(n, dtype=bool)
        keep[cand] = True
        choices = {s: list(range(row_groups[s], row_groups[s + 1])) for s in range(n)}
        while True:
            ok = {s: [c for c in choices[s] if keep[s] and all(
                keep[t] for t in m.indices[m.indptr[c]:m.indptr[c + 1]])] for s in range(n)}
            src, dst = [], []
            for s in range(n):
                for c in ok[s]:
                    for t in m.indices[m.indptr[c]:m.indptr[c + 1]]:
                        src.append(s)
                        dst.append(t)
            g = sp.csr_array((np.ones(len(src)), (src, dst)), shape=(n, n))
            _, comp = connected_components(g, connection="strong")
            ok = {s: [c for c in ok[s] if all(comp[t] == comp[s] for t in
                                              m.indices[m.indptr[c]:m.indptr[c + 1]])]
                  for s in range(n)}
            new = np.array([keep[s] and bool(ok[s]) for s in range(n)])
            if np.array_equal(new, keep):
                break
            keep = new
        np.testing.assert_array_equal(alive, keep[cand])


DAMAGE_CHILD = r"""
import json, marshal, sys
import numpy as np, scipy.sparse as sp
from mitld_lp.solvers import compiled_graph
from mitld_lp.util import kernel_files, kernel_loader

kernel = compiled_graph.strong_components
rng = np.random.default_rng(3)
g = sp.csr_array((rng.random((60, 60)) < 0.04).astype(np.int8))
args = (g.indptr.astype(np.int64), g.indices.astype(np.int64), np.bool_(False))
key = kernel_loader.type_key(args)
expected = kernel.numba_dispatcher()(*args)
kernel(*args)  # numba's call writes the file
py_file = kernel.py_func.__code__.co_filename
name = kernel_files.file_name(py_file, kernel.__qualname__, key)
(path,) = [d / name for d in kernel_files.directories(py_file) if (d / name).is_file()]
out = {"folder": str(path.parent)}
for damage in sys.argv[1:]:
    kernel._calls.pop(key, None)
    data = path.read_bytes()
    meta, obj = kernel_files.unpack(data)
    if damage == "flip":
        bad = bytearray(data)
        bad[-100] ^= 0xFF
        bad = bytes(bad)
    elif damage == "truncate":
        bad = data[: len(data) // 2]
    elif damage == "garbage":
        bad = b"not a cache file"
    elif damage == "callee":  # a kernel of another module compiled in, since changed
        other = dict(meta, sources=(("mitld_lp.solvers.level_kernels", "0" * 64),))
        bad = kernel_files.pack(marshal.dumps(other), obj)
    else:  # a whole, well-formed file for another numba / CPU
        other = dict(meta, key=meta["key"].replace(b"x86_64", b"aarch64"))
        bad = kernel_files.pack(marshal.dumps(other), obj)
    good_before = kernel_loader._load(kernel, key) is not None
    path.write_bytes(bad)
    refused = kernel_loader._load(kernel, key) is None
    kernel._calls.pop(key, None)  # as in a fresh process
    got = kernel(*args)  # numba's call, the file written again
    out[damage] = {"good_before": good_before, "refused": refused,
                   "n": bool(got[0] == expected[0]),
                   "labels": bool(np.array_equal(got[1], expected[1])),
                   "rewritten": path.read_bytes() != bad,
                   "linked_after": kernel_loader._load(kernel, key) is not None}
print(json.dumps(out))
"""


def test_damaged_or_foreign_file_falls_back_and_is_rewritten(tmp_path: Path) -> None:
    """Each damage to a cache file: refused, numba's call gives the same arrays, and the
    file is written again and links.  In a child process with a cache folder of its own
    (``NUMBA_CACHE_DIR``): damaging the shared cache file raced other test processes
    that read it (one linked numba's call instead, another found it half written)."""
    damages = ["flip", "truncate", "foreign", "garbage", "callee"]
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    done = subprocess.run([sys.executable, "-c", DAMAGE_CHILD, *damages],
                          capture_output=True, text=True, env=env, cwd=str(tmp_path))
    assert done.returncode == 0, done.stderr[-3000:]
    out = json.loads(done.stdout.strip().splitlines()[-1])
    assert Path(out["folder"]).is_relative_to(tmp_path / "cache")
    for damage in damages:
        assert out[damage] == {"good_before": True, "refused": True, "n": True,
                               "labels": True, "rewritten": True,
                               "linked_after": True}, damage


CHILD = r"""
import json, sys
import numpy as np
from mitld_lp.solvers import compiled_graph
from mitld_lp.util import kernel_loader
ptr = np.array(PTR, dtype=np.int64)
succ = np.array(SUCC, dtype=np.int64)
n, label = compiled_graph.strong_components(ptr, succ, np.bool_(False))
print(json.dumps({"numba": "numba" in sys.modules, "loaded": kernel_loader.loaded_count(),
                  "n": int(n), "label": label.tolist()}))
"""


def test_warm_process_does_not_import_numba() -> None:
    rng = np.random.default_rng(5)
    ptr, succ = _graph(rng, 50, 0.05)
    args = (ptr, succ, np.bool_(False))
    _linked(compiled_graph.strong_components, args)  # the cache warm
    expected = compiled_graph.strong_components.numba_dispatcher()(*args)
    code = CHILD.replace("PTR", repr(ptr.tolist())).replace("SUCC", repr(succ.tolist()))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=str(ROOT), check=True)
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["numba"] is False
    assert got["loaded"] == 1
    assert got["n"] == int(expected[0])
    assert got["label"] == expected[1].tolist()
