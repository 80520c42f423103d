"""numba's runtime module read from its own cache (:mod:`mitld_lp.util.nrt_cache`): a
file is loaded only where it is whole and of exactly this process's key; a stale or
foreign file is compiled again and rewritten; the kernels give the answers of a NumPy
computation written here whichever way the runtime came (loaded or compiled).

Each process case runs in a fresh process (a process initialises numba's runtime once)
with the runtime's cache file in a temporary directory; the kernels themselves use the
package's numba cache as every test does (cold in CI: they compile then)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.util import nrt_cache

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import ctypes, json, sys
from pathlib import Path
import numpy as np, scipy.sparse as sp
from mitld_lp.util import numba_narrow, nrt_cache
numba_narrow.import_numba()
assert numba_narrow.install()
base = Path(sys.argv[1])
nrt_cache.cache_file = lambda name="nrt": base / name  # the test's own directory
from numba.core.registry import cpu_target
from numba.core.runtime import rtsys
ctx = cpu_target.target_context
codegen = ctx.codegen()
loads = []
unserialize = codegen.unserialize_library
def counted(state):
    if state[0] == "nrt":  # the runtime's library (the kernels' are loaded so too)
        loads.append(state[0])
    return unserialize(state)
codegen.unserialize_library = counted
nrt_cache.initialize(ctx)  # what the narrow load does at a cached kernel's first call
assert rtsys._init
# the runtime's own machine code, called directly: an atomic add returns the new count
add = ctypes.CFUNCTYPE(ctypes.c_size_t, ctypes.POINTER(ctypes.c_size_t))(
    rtsys.library.get_pointer_to_function("nrt_atomic_add"))
cell = ctypes.c_size_t(41)
after = add(ctypes.byref(cell))
# a kernel that allocates arrays (its runtime calls) on a chain of 5 states
from mitld_lp.solvers import kernels
P = np.array(json.loads(sys.argv[2]))
exits = np.array(json.loads(sys.argv[3]))
inner = sp.csr_array(P)
n = P.shape[0]
prep = kernels.Prepared(inner, np.arange(n + 1))
local = np.column_stack([np.zeros(n), np.ones(n)])
done, over = kernels.compiled_sweeps(prep, np.column_stack([exits, exits]), local, 1e-13,
                                     100000)
# a function compiled now (no cache) links against the runtime's library as it came
import numba
@numba.njit
def made(n):
    a = np.zeros(n)
    for i in range(n):
        a[i] = 1.5 * i
    return a, a.sum()
fresh, total = made(5)
print(json.dumps({"loads": loads, "after": after, "cell": cell.value,
                  "fresh": fresh.tolist(), "total": total,
                  "lower": local[:, 0].tolist(), "upper": local[:, 1].tolist(),
                  "over": over}))
"""

# a chain of 5 states, one choice each: P (with self-loops) and each state's exit
# probability to the goal; what is left leaves to a loss
P = [[0.2, 0.3, 0.0, 0.0, 0.1],
     [0.0, 0.5, 0.25, 0.0, 0.0],
     [0.1, 0.0, 0.0, 0.6, 0.0],
     [0.0, 0.0, 0.3, 0.4, 0.2],
     [0.25, 0.0, 0.0, 0.0, 0.5]]
EXITS = [0.3, 0.1, 0.2, 0.05, 0.15]


def _child(base: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, "-c", CHILD, str(base), json.dumps(P),
                           json.dumps(EXITS)], capture_output=True, text=True, env=env,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def _exact() -> np.ndarray:
    """The chain's probability of the goal: x = exits + P x, by a linear solve."""
    p = np.array(P)
    return np.linalg.solve(np.eye(len(p)) - p, np.array(EXITS))


def _cache_files(base: Path) -> list[Path]:
    return sorted(base.glob("nrt-*.bin"))


def _check_answer(out: dict) -> None:
    exact = _exact()
    lower, upper = np.array(out["lower"]), np.array(out["upper"])
    assert out["over"] < 1.0
    assert np.all(lower <= exact + 1e-12) and np.all(upper >= exact - 1e-12)
    assert np.all(upper - lower <= 1e-13)
    assert out["after"] == 42 and out["cell"] == 42  # the atomic add's own result
    assert out["fresh"] == [0.0, 1.5, 3.0, 4.5, 6.0] and out["total"] == 15.0


def test_compiled_then_loaded_then_stale_recompiled(tmp_path: Path) -> None:
    first = _child(tmp_path)  # no file: compiled, written
    assert first["loads"] == []
    _check_answer(first)
    files = _cache_files(tmp_path)
    assert len(files) == 1
    second = _child(tmp_path)  # the same key: loaded
    assert second["loads"] == ["nrt"]
    _check_answer(second)
    assert second["lower"] == first["lower"] and second["upper"] == first["upper"]
    # stale: the same file name, another key inside (as a file of another numba or CPU)
    data = files[0].read_bytes()
    key_length = int.from_bytes(data[len(nrt_cache.MAGIC):len(nrt_cache.MAGIC) + 8], "little")
    start = len(nrt_cache.MAGIC) + 24 + 32
    key = data[start:start + key_length]
    obj_bc = data[start + key_length:]
    n_obj = int.from_bytes(data[len(nrt_cache.MAGIC) + 8:len(nrt_cache.MAGIC) + 16], "little")
    foreign = key.replace(b"'", b'"', 1)  # one byte of the key differs
    files[0].write_bytes(nrt_cache._pack(foreign, obj_bc[:n_obj], obj_bc[n_obj:]))
    third = _child(tmp_path)
    assert third["loads"] == []  # compiled again, not loaded
    _check_answer(third)
    assert files[0].read_bytes() == data  # and rewritten with this process's key


def test_damaged_file_is_compiled_again(tmp_path: Path) -> None:
    _child(tmp_path)
    (path,) = _cache_files(tmp_path)
    data = bytearray(path.read_bytes())
    data[-100] ^= 0xFF  # a byte of the machine code or bitcode flipped
    path.write_bytes(bytes(data))
    out = _child(tmp_path)
    assert out["loads"] == []
    _check_answer(out)


@pytest.mark.parametrize("damage", ["magic", "truncated", "key", "digest", "longer"])
def test_unpack_refuses_all_but_a_whole_file_of_the_key(damage: str) -> None:
    key, obj, bc = b"the key", b"\x01\x02object", b"BC\xc0\xdebitcode"
    data = nrt_cache._pack(key, obj, bc)
    assert nrt_cache._unpack(data, key) == (obj, bc)
    bad = {"magic": b"X" + data[1:], "truncated": data[:-1],
           "key": data, "digest": data[:len(nrt_cache.MAGIC) + 24] + bytes(32)
           + data[len(nrt_cache.MAGIC) + 56:], "longer": data + b"\x00"}[damage]
    assert nrt_cache._unpack(bad, b"the kez" if damage == "key" else key) is None
