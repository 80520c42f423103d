"""numba's disk cache shared by processes that compile at once (mitld_lp.util.numba_cache).

numba writes a cache entry as: read the index, take the first free data-file number,
write the index, then the data.  Two processes saving two signatures of one function at
once can take the same number, and the index then names the other signature's machine
code.  The lock makes each save and each load one step; these tests check that the lock
is held inside numba's index-and-data read and write (a second open file description of
the lock file cannot take it there), and that two processes made to save at the same
moment leave a cache from which a third process loads each signature's own code."""

from __future__ import annotations

import fcntl
import importlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mitld_lp.util import numba_cache

SOURCE = textwrap.dedent("""
    import numba

    @numba.njit(cache=True)
    def total(x):
        s = x[0] * 0
        for v in x:
            s += v
        return s
""")


def _taken_by_someone(cache_path: str) -> bool:
    """Whether the lock file's lock is held (tried from a new open file description)."""
    fd = os.open(os.path.join(cache_path, numba_cache.LOCK_NAME), os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


def test_each_save_and_load_holds_the_cache_directorys_lock(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from numba.core import caching

    assert numba_cache.install()
    (tmp_path / "lockmod_a.py").write_text(SOURCE)
    monkeypatch.syspath_prepend(str(tmp_path))
    seen: list[tuple[str, bool]] = []
    save, load = caching.IndexDataCacheFile.save, caching.IndexDataCacheFile.load

    def spy_save(self, key, data):  # noqa: ANN001, ANN202
        seen.append(("save", _taken_by_someone(self._cache_path)))
        return save(self, key, data)

    def spy_load(self, key):  # noqa: ANN001, ANN202
        seen.append(("load", _taken_by_someone(self._cache_path)))
        return load(self, key)

    monkeypatch.setattr(caching.IndexDataCacheFile, "save", spy_save)
    monkeypatch.setattr(caching.IndexDataCacheFile, "load", spy_load)
    mod = importlib.import_module("lockmod_a")
    assert mod.total(np.arange(5, dtype=np.int64)) == 10  # a miss: load, compile, save
    assert mod.total(np.arange(5, dtype=np.float64) + 0.5) == 12.5
    kinds = [k for k, _ in seen]
    assert kinds.count("save") == 2 and "load" in kinds
    assert all(held for _, held in seen), seen
    sys.modules.pop("lockmod_a")


CHILD = textwrap.dedent("""
    import importlib, os, sys, time
    where, which, barrier = sys.argv[1:4]
    sys.path.insert(0, where)
    from numba.core import caching
    from mitld_lp.util import numba_cache
    numba_cache.install()
    save_index = caching.IndexDataCacheFile._save_index

    def _save_index(self, overloads):
        # each process has read the index and taken a data-file number: wait here for
        # the other (at most 3 s: under the lock the other waits for this one)
        open(os.path.join(barrier, str(os.getpid())), "w").close()
        start = time.monotonic()
        while len(os.listdir(barrier)) < 2 and time.monotonic() - start < 3:
            time.sleep(0.005)
        return save_index(self, overloads)

    caching.IndexDataCacheFile._save_index = _save_index
    import numpy as np
    mod = importlib.import_module("lockmod_b")
    x = np.arange(5, dtype=np.int64) if which == "int" else np.arange(5.0) + 0.5
    print(mod.total(x))
""")

READER = textwrap.dedent("""
    import importlib, sys
    sys.path.insert(0, sys.argv[1])
    import numpy as np
    mod = importlib.import_module("lockmod_b")
    print(mod.total(np.arange(5, dtype=np.int64)), mod.total(np.arange(5.0) + 0.5),
          sum(mod.total.stats.cache_hits.values()), sum(mod.total.stats.cache_misses.values()))
""")


def test_two_processes_saving_at_once_leave_each_signature_its_own_code(
        tmp_path: Path) -> None:
    (tmp_path / "lockmod_b.py").write_text(SOURCE)
    barrier = tmp_path / "barrier"
    barrier.mkdir()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(Path(numba_cache.__file__).parents[2]), os.environ.get("PYTHONPATH", "")])}
    env.pop("NUMBA_CACHE_DIR", None)  # the cache beside the module, in tmp_path
    kids = [subprocess.Popen([sys.executable, "-c", CHILD, str(tmp_path), which,
                              str(barrier)], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
            for which in ("int", "float")]
    outs = [k.communicate(timeout=300) for k in kids]
    assert all(k.returncode == 0 for k in kids), outs
    assert [o.strip() for o, _ in outs] == ["10", "12.5"]
    assert len(os.listdir(barrier)) == 2  # both wrote an entry
    got = subprocess.run([sys.executable, "-c", READER, str(tmp_path)], env=env,
                         capture_output=True, text=True, timeout=300)
    assert got.returncode == 0, got.stderr
    assert got.stdout.split() == ["10", "12.5", "2", "0"]  # both loaded, none compiled
