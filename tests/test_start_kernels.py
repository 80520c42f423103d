"""Fixed costs of a process on small instances: the kernel gates' cache check from one
listing of each folder (:func:`mitld_lp.util.kernel_files.listing`), and ``numpy.ma``
left for later when the package's ``np.unique`` imports it (:mod:`mitld_lp.masked_later`,
each in a fresh interpreter: what is imported is the point)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.util import kernel_files, kernel_loader

ROOT = Path(__file__).resolve().parent.parent


# --- the cache check from one folder listing -----------------------------------------


@pytest.fixture
def cache_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A module file and numba's cache folder for it (``NUMBA_CACHE_DIR``); the
    listings of the folder forgotten after."""
    module = tmp_path / "src" / "mod_k.py"
    module.parent.mkdir()
    module.write_text("x = 1\n")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    (folder,) = kernel_files.directories(str(module))
    folder.mkdir(parents=True)
    yield module, folder
    kernel_files.forget_listing(folder)


def _by_glob(module: Path, folder: Path, qualname: str) -> bool:
    """The check as it was made before: a glob of the kernel's files, each not older
    than the module's source."""
    source = module.stat().st_mtime_ns
    return any(f.stat().st_mtime_ns >= source
               for f in folder.glob(f"{module.stem}.{qualname}-*{kernel_files.SUFFIX}"))


def test_listing_sees_a_kernel_written_after_the_first_listing(cache_dir) -> None:
    module, folder = cache_dir
    assert not kernel_loader.cached(str(module), "walk")  # listed: nothing there
    assert kernel_files.listing(folder) == {}
    name = kernel_files.file_name(str(module), "walk", (("int",),))
    kernel_files.write(folder / name, b"payload")
    assert kernel_loader.cached(str(module), "walk")
    assert kernel_files.listing(folder) == {f"{module.stem}.walk": [name]}
    # a kernel of a name that starts like it is another kernel
    assert not kernel_loader.cached(str(module), "wal")
    assert not kernel_loader.cached(str(module), "walk2")


def test_listing_sees_a_file_another_process_wrote(cache_dir) -> None:
    """Written without :func:`kernel_files.write` (another process): the folder's
    modification time moved, so the listing is made again."""
    module, folder = cache_dir
    assert not kernel_loader.cached(str(module), "sweep")
    stamp = folder.stat().st_mtime_ns
    name = kernel_files.file_name(str(module), "sweep", (("float",),))
    (folder / name).write_bytes(b"x")
    os.utime(folder, ns=(stamp + 10**9, stamp + 10**9))  # a clock that moved
    assert kernel_loader.cached(str(module), "sweep")
    (folder / name).unlink()
    os.utime(folder, ns=(stamp + 2 * 10**9, stamp + 2 * 10**9))
    assert not kernel_loader.cached(str(module), "sweep")


def test_cached_agrees_with_a_glob(cache_dir) -> None:
    """Several kernels, files older and newer than the source, checked against the
    glob the check made before."""
    module, folder = cache_dir
    source = module.stat().st_mtime_ns
    kernels = ["a", "b", "c", "ab", "b_c"]
    for i, (qualname, age) in enumerate([("a", -5), ("b", 5), ("ab", 5), ("b_c", -1),
                                         ("b_c", 3), ("c", -3)]):
        path = folder / kernel_files.file_name(str(module), qualname, (("int",), i))
        kernel_files.write(path, b"k")
        os.utime(path, ns=(source + age * 10**9, source + age * 10**9))
    (folder / "mod_k.c-0123.kobj.tmp").write_bytes(b"half written")  # not a cache file
    got = {k: kernel_loader.cached(str(module), k) for k in kernels}
    assert got == {k: _by_glob(module, folder, k) for k in kernels}
    assert got == {"a": False, "b": True, "c": False, "ab": True, "b_c": True}


def test_no_folder_is_no_kernel(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "nowhere"))
    module = tmp_path / "m.py"
    module.write_text("")
    assert kernel_files.listing(tmp_path / "nowhere") == {}
    assert not kernel_loader.cached(str(module), "f")


# --- numpy.ma left for later ---------------------------------------------------------


def _run(code: str, plain: bool = False) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONDONTWRITEBYTECODE", "MITLD_LP_PLAIN_IMPORTS")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    if plain:
        env["MITLD_LP_PLAIN_IMPORTS"] = "1"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


#: NumPy's unique called from code of the package (a module named ``mitld_lp.*``) and
#: from the program (``__main__``) after the package imported a module.
PROBE = r"""
import json, sys, types
import numpy as np
import mitld_lp.mdp  # a module of the package: its finder is in place
out = {"before": "numpy.ma" in sys.modules}
values = np.array([5, 3, 5, 1, 3, 9, 1], dtype=np.int64)
package = {"__name__": "mitld_lp.probe", "np": np, "values": values}
exec("found = np.unique(values)", package)
out["package_unique"] = package["found"].tolist()
out["ma_module"] = "numpy.ma" in sys.modules
out["ma_body_ran"] = "numpy.ma.core" in sys.modules
held = np.ma  # numpy's attribute: the module itself, its body not run
class Sub(np.ndarray):
    pass
sub = np.array([2, 2, 7]).view(Sub)
exec("found_sub = np.unique(sub)", dict(package, sub=sub))
out["sub_body_ran"] = "numpy.ma.core" in sys.modules
import numpy.ma as ma
import numpy.ma.core as core
out["same"] = held is ma is np.ma is sys.modules["numpy.ma"]
out["plain_type"] = type(ma) is types.ModuleType
out["is_masked_real"] = ma.is_masked is core.is_masked
m = ma.masked_array([1, 2, 3, 4], mask=[0, 1, 0, 0])
out["masked_sum"] = int(m.sum())
out["masked_unique"] = np.unique(ma.masked_array([3, 1, 3], mask=[0, 0, 1])).tolist()
out["is_masked"] = [bool(ma.is_masked(m)), bool(ma.is_masked(values))]
out["dir"] = "masked_array" in dir(ma)
print(json.dumps(out, default=str))
"""


def test_numpy_ma_put_off_for_the_packages_unique() -> None:
    got = _run(PROBE)
    assert got["before"] is False
    assert got["package_unique"] == sorted({5, 3, 1, 9})
    assert got["ma_module"] is True and got["ma_body_ran"] is False
    # an ndarray subclass is asked of the real is_masked: the body runs then
    assert got["sub_body_ran"] is True
    assert got["same"] and got["plain_type"] and got["is_masked_real"] and got["dir"]
    assert got["masked_sum"] == 1 + 3 + 4
    assert got["is_masked"] == [True, False]
    # the plain imports (the finder left out) give the same answers
    plain = _run(PROBE, plain=True)
    assert plain["ma_body_ran"] is True
    for key in ("package_unique", "same", "plain_type", "is_masked_real", "masked_sum",
                "masked_unique", "is_masked", "dir"):
        assert got[key] == plain[key], key


def test_the_programs_own_unique_imports_numpy_ma() -> None:
    code = r"""
import json, sys
import numpy as np
import mitld_lp.mdp
found = np.unique(np.array([4, 4, 2]))
print(json.dumps({"found": found.tolist(), "body": "numpy.ma.core" in sys.modules}))
"""
    assert _run(code) == {"found": [2, 4], "body": True}


def test_numpy_ma_first_use_in_two_threads() -> None:
    """Two threads reading names of the put-off module at once both get the real
    objects (the second waits for the body the first runs)."""
    code = r"""
import json, sys, threading
import numpy as np
import mitld_lp.mdp
exec("np.unique(np.arange(3))", {"__name__": "mitld_lp.probe", "np": np})
assert "numpy.ma.core" not in sys.modules
ma = np.ma
seen, errors = [], []
def read():
    try:
        seen.append((ma.masked_array, ma.MaskedArray, ma.nomask))
    except Exception as exc:
        errors.append(repr(exc))
threads = [threading.Thread(target=read) for _ in range(4)]
for t in threads:
    t.start()
for t in threads:
    t.join()
import numpy.ma.core as core
ok = all(s == (core.masked_array, core.MaskedArray, core.nomask) for s in seen)
print(json.dumps({"errors": errors, "n": len(seen), "ok": ok}))
"""
    assert _run(code) == {"errors": [], "n": 4, "ok": True}


# --- remembered look-ups -------------------------------------------------------------


def test_directories_follow_the_environment(tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    module = str(tmp_path / "pkg" / "mod.py")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "one"))
    first = kernel_files.directories(module)
    first.append(Path("/elsewhere"))  # the caller's list is its own
    assert kernel_files.directories(module) == first[:1]
    assert first[0].parent == tmp_path / "one"
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "two"))
    assert [d.parent for d in kernel_files.directories(module)] == [tmp_path / "two"]
    monkeypatch.delenv("NUMBA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    found = kernel_files.directories(module)
    assert found[0] == tmp_path / "pkg" / "__pycache__"
    assert found[1].parent == tmp_path / "xdg" / "numba"
    # a relative cache folder follows the working directory
    monkeypatch.setenv("NUMBA_CACHE_DIR", "rel")
    monkeypatch.chdir(tmp_path)
    here = kernel_files.directories(module)[0]
    monkeypatch.chdir(tmp_path / "pkg" if (tmp_path / "pkg").is_dir() else "/")
    assert here.parent == tmp_path / "rel"
    assert kernel_files.directories(module)[0].parent != here.parent


def test_resolver_remembers_the_process_symbols() -> None:
    import ctypes

    from mitld_lp.util import elf_runtime

    resolve = elf_runtime.resolver({"strlen": 1234})
    assert resolve("strlen") == 1234  # the explicit address first
    libc = ctypes.CDLL(None)
    direct = ctypes.cast(libc["strchr"], ctypes.c_void_p).value
    assert resolve("strchr") == direct and resolve("strchr") == direct
    assert resolve("no_such_symbol_mitld_lp") is None
    assert resolve("no_such_symbol_mitld_lp") is None
