"""The sources a cached kernel was compiled from (:mod:`mitld_lp.util.kernel_loader`):
its own module's and those of the kernels of other modules compiled into it, and numba's
disk cache of a kernel flushed where one of those others has changed.

numba's own cache checks a kernel's own file only (its time and size): after an edit of a
module whose kernels another module's kernel calls, numba would load the caller's old
machine code, with the old callee inside, and the loader would file it under the new
sources.  The loader's cache file names every callee's source; where one differs, the
loader marks the kernel :data:`STALE`, and before numba's call
:func:`flush_numba_cache` has numba compile it afresh."""

from __future__ import annotations

import hashlib
import importlib.util
import sys
from typing import Any

__all__ = ["STALE", "callee_sources", "flush_numba_cache", "kernel_modules", "source_hash"]

STALE: set[tuple[str, str]] = set()
"""Kernels (module, qualified name) whose cache file names a kernel of another module
whose source has changed since: numba's disk cache of them is as stale."""

_sources: dict[str, str] = {}


def callee_sources(modules: Any) -> tuple:
    """``(module, SHA-256 of its source)`` of each of our modules named (the modules of
    the kernels linked into a kernel: their environments name them), or () where one
    cannot be read: a kernel's key holds its own module's source, and these hold the
    source of every kernel compiled into it from another module."""
    out = []
    for name in sorted(set(modules)):
        module = sys.modules.get(name)
        path = getattr(module, "__file__", None)
        if path is None:
            spec = importlib.util.find_spec(name)
            path = None if spec is None else spec.origin
        if path is None:
            return ()
        try:
            out.append((name, source_hash(path)))
        except OSError:
            return ()
    return tuple(out)


def kernel_modules(module: str) -> set[str]:
    """Our modules (``mitld_lp.*``, not ``module`` itself) whose kernels the kernels of
    ``module`` may call: those of the kernels in its globals, and theirs, transitively.
    numba names a callee's module in the caller's environments only where the callee
    needs one; a callee inlined, or one that boxes nothing, is named by none, and its
    edit would leave the caller's cached machine code stale unseen.  A kernel is an
    object whose own ``__dict__`` holds a ``py_func`` (the loader's kernels, numba's
    dispatchers); a module's other globals are not asked (a lazy numba would import it)."""
    seen, todo = {module}, [module]
    while todo:
        found = sys.modules.get(todo.pop())
        for value in list(getattr(found, "__dict__", {}).values()):
            own = getattr(value, "__dict__", None)
            func = own.get("py_func") if isinstance(own, dict) else None
            name = getattr(func, "__module__", None)
            if isinstance(name, str) and name.startswith("mitld_lp.") and name not in seen:
                seen.add(name)
                todo.append(name)
    seen.discard(module)
    return seen


def source_hash(path: str) -> str:
    """The SHA-256 of the file ``path`` (read once a process)."""
    digest = _sources.get(path)
    if digest is None:
        with open(path, "rb") as f:
            digest = _sources[path] = hashlib.sha256(f.read()).hexdigest()
    return digest


def flush_numba_cache(kernel: Any, dispatcher: Any) -> None:
    """Have numba compile ``kernel`` afresh, with the kernels of other modules as they are
    now, and save that (its dispatcher's ``recompile``: numba's disk index of it emptied,
    the signatures this process has compiled already compiled again), once a process."""
    STALE.discard((kernel.__module__, kernel.__qualname__))
    cache = getattr(dispatcher, "_cache", None)
    if cache is None or not hasattr(cache, "_cache_path"):
        return
    from mitld_lp.util import numba_cache

    with numba_cache.locked(cache._cache_path):
        if hasattr(dispatcher, "recompile"):
            dispatcher.recompile()
        elif hasattr(cache, "flush"):
            cache.flush()
