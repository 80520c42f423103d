"""numba's disk cache shared safely by processes that compile at the same time.

numba (0.68 and earlier; its issues #4807 and #10128) writes a new cache entry by
reading the function's index, taking the first free data-file number, writing the index,
and only then the data file.  Two processes that compile two signatures of one function
at once (two test workers, two sweep workers on a fresh installation) can both take
number 1: the index then names, for one signature, the machine code of the other, and a
later process that loads it runs code compiled for other argument types (a wrong result
or a segmentation fault).  A process that reads between the index and the data write
can also load a stale data file.

:func:`install` takes an exclusive ``flock`` on a lock file in the function's cache
directory around each save and each load of a cache entry, so that an index and its
data are always written and read together.  A process that finds the lock taken waits;
a compile itself runs outside the lock.  Where ``fcntl`` is missing (Windows) nothing is
changed.  The kernels loaded are numba's own cache entries either way.
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["LOCK_NAME", "install", "installed", "locked"]

LOCK_NAME = ".mitld_lp_cache.lock"
"""The lock file's name in each cache directory."""

_installed = False
_held = threading.local()  # the cache directories this thread holds the lock of


def installed() -> bool:
    """Whether the cache's saves and loads take the lock in this process."""
    return _installed


@contextlib.contextmanager
def locked(cache_path: str) -> Iterator[None]:
    """The lock of the cache directory ``cache_path`` held (re-entrant in a thread); no
    lock where the directory cannot be made or the lock file opened (numba then fails or
    skips the cache as it would)."""
    import fcntl

    held = getattr(_held, "paths", None)
    if held is None:
        held = _held.paths = set()
    if cache_path in held:
        yield
        return
    try:
        os.makedirs(cache_path, exist_ok=True)
        fd = os.open(os.path.join(cache_path, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        held.add(cache_path)
        try:
            yield
        finally:
            held.discard(cache_path)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def install() -> bool:
    """Have numba's cache take the lock around each save and load; False (nothing
    changed) where ``fcntl`` or numba's cache driver is not as expected."""
    global _installed
    if _installed:
        return True
    try:
        import fcntl  # noqa: F401 - POSIX only

        from numba.core import caching
    except ImportError:
        return False
    save = getattr(caching.Cache, "save_overload", None)
    load = getattr(caching.Cache, "load_overload", None)
    if save is None or load is None:
        return False

    def save_overload(self: Any, sig: Any, data: Any) -> Any:
        with locked(self.cache_path):
            return save(self, sig, data)

    def load_overload(self: Any, sig: Any, target_context: Any) -> Any:
        with locked(self.cache_path):
            return load(self, sig, target_context)

    caching.Cache.save_overload = save_overload
    caching.Cache.load_overload = load_overload
    _installed = True
    return True
