"""A chain's layered blocks by one compiled call, for the certificate's chain
(:mod:`mitld_lp.solvers.certify_chain`): a module of its own, since it makes the
analysis's :class:`~mitld_lp.solvers.graph.Blocks` and
:mod:`mitld_lp.solvers.certify_compiled` imports no module of the analysis (the graph
module reaches it through the analysis's gates)."""

from __future__ import annotations

import numpy as np

from mitld_lp.solvers import certify_compiled
from mitld_lp.solvers.graph import Blocks
from mitld_lp.solvers.result import read_only

__all__ = ["BLOCKS_KERNEL", "blocks_cached", "compiled_chain_blocks"]

BLOCKS_KERNEL = ("mitld_lp.solvers.certify_kernels", "chain_blocks")
"""The chain's blocks' kernel (:func:`compiled_chain_blocks`), asked for its cache file
once a process (:func:`blocks_cached`)."""

_BLOCKS_WARM: list[bool] = []  # whether BLOCKS_KERNEL has a cache file, once a process


def blocks_cached() -> bool:
    """Whether the kernel loader would link :data:`BLOCKS_KERNEL` from its cache
    (:func:`~mitld_lp.util.kernel_loader.module_cached`, through the loader
    :mod:`~mitld_lp.solvers.certify_compiled` holds), looked up once a process, as the
    sibling gates do (:func:`~mitld_lp.solvers.certify_compiled.rounds_cached`): a cold
    cache never makes a certificate pay numba's compile."""
    if not _BLOCKS_WARM:
        _BLOCKS_WARM.append(bool(
            certify_compiled.kernel_loader.module_cached(*BLOCKS_KERNEL)))
    return _BLOCKS_WARM[0]


def compiled_chain_blocks(comp: np.ndarray, level: np.ndarray, self_loop: np.ndarray,
                          ) -> Blocks | None:
    """:func:`~mitld_lp.solvers.graph.blocks_from` of a chain's states by one compiled
    call (:func:`~mitld_lp.solvers.certify_kernels.chain_blocks`): the same
    :class:`~mitld_lp.solvers.graph.Blocks`, array for array.  ``comp``: the states'
    components (ids of the support graph's), ``level``: every support component's level,
    non-negative at each of ``comp`` (the caller's check, :func:`~mitld_lp.solvers.
    certify_chain._solve`'s layers).  None where the NumPy calls run instead: fewer than
    :data:`~mitld_lp.solvers.certify_compiled.COMPILED_CHECK_MIN_ROWS` states, no
    compiled kernel loaded yet in this process, the kernel not in the loader's cache
    (:func:`blocks_cached`), a negative id, or ids past an int32."""
    n = int(comp.shape[0])
    # the certificate's gates as :mod:`~mitld_lp.solvers.certify_compiled` holds them
    # (its size and its loader: one switch for every compiled path of the certificate)
    if (n < certify_compiled.COMPILED_CHECK_MIN_ROWS
            or not certify_compiled.kernel_loader.compiled_paid()
            or not blocks_cached()
            or comp.dtype.kind not in "iu" or level.dtype.kind not in "iu"
            or int(comp.min()) < 0 or int(comp.max()) >= level.shape[0]
            or level.shape[0] >= 2**31 - 1):
        return None
    try:
        from mitld_lp.solvers.certify_kernels import chain_blocks
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    # int32 whatever the caller's, the levels read-only: one signature, one cache file
    # (the ids fit: below the levels' count, checked above)
    levels = np.ascontiguousarray(level, dtype=np.int32).view()
    levels.flags.writeable = False
    dense, dlevel, size, order, starts = chain_blocks(
        np.ascontiguousarray(comp, dtype=np.int32), levels)
    return Blocks(component=read_only(dense), level=read_only(dlevel), size=read_only(size),
                  by_level=read_only(order), level_starts=read_only(starts),
                  self_loop=read_only(np.asarray(self_loop, dtype=np.float64)))
