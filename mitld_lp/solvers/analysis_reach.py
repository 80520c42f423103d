"""The product's components and reach for the analysis in one compiled pass
(:func:`~mitld_lp.solvers.analysis_kernels.components_reach`), where
:func:`~mitld_lp.solvers.graph.components_reaching` would take SciPy's route (its state
graph with the duplicates merged, SciPy's strong components, and a breadth-first search
of the graph reversed for each seed set, or a search of the condensation).  The same
record: the components labelled alike (in the same index type), ``level`` None and the
levels ``later()`` walks from the same condensation, and the same reached states; a
minimum's ``Prob1A`` search (the states reaching its prob-0 states,
:func:`~mitld_lp.solvers.value_one.prob1a_first`) read from the same pass, one more bit.
The levels ``later()`` gives are found by one compiled pass over the components in the
order the search completed them (:func:`~mitld_lp.solvers.analysis_kernels.
component_levels`, where its cache file is there: no state graph kept, no condensation,
no NumPy round a level; QVBS zeroconf 1000-4: 0.032 -> 0.011 s), the same integers.

Taken only where the kernel's load is paid and its cache file is there
(:func:`~mitld_lp.solvers.analysis_gates.warm`: a solve never compiles it), on an int32
pattern that :func:`~mitld_lp.solvers.compiled_graph.fits` in int32, of at least
:data:`~mitld_lp.solvers.analysis_gates.PAID_MIN_ENTRIES` entries (read there, so that
a caller turning the compiled walks off turns this one off too), and whose state graph
is past :data:`~mitld_lp.util.traversal.SMALL`; else None, and the caller takes SciPy's."""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.solvers import analysis_gates
from mitld_lp.solvers.analysis_gates import component_walks, warm
from mitld_lp.solvers.graph import Levels, condensation, graph_view, leveled
from mitld_lp.util import kernel_loader
from mitld_lp.util.arrays import index_dtype
from mitld_lp.util.traversal import SMALL

__all__ = ["FUSED", "LEVELS", "fused_components_reaching"]

FUSED = ("mitld_lp.solvers.analysis_kernels", "components_reach")
LEVELS = ("mitld_lp.solvers.analysis_kernels", "component_levels")
"""The kernels (module, name) whose cache files are asked for."""


def _kernels() -> Any:
    """The fused kernel's module where its route is taken (module docs), else None."""
    if not kernel_loader.compiled_paid() or not warm(FUSED):
        return None
    try:
        from mitld_lp.solvers import analysis_kernels
    except ImportError:  # pragma: no cover - numba is a dependency of the solvers
        return None
    return analysis_kernels


def fused_components_reaching(matrix: sp.csr_array, row_groups: np.ndarray, seeds: np.ndarray,
                              extra: np.ndarray | None = None,
                              ) -> tuple[Levels, np.ndarray, np.ndarray | None, np.ndarray] | None:
    """``(found, reach, reached, crowd)``: :func:`~mitld_lp.solvers.graph.
    components_reaching`'s first two for ``seeds`` (``(n, k)`` bool) from one compiled
    pass, the states reaching an ``extra`` state (None without it), and
    :func:`~mitld_lp.solvers.quotient_order.crowded`'s states of ``found.component``
    (the same array: int64 and empty where every component is one state); None where
    its route is not taken (module docs)."""
    n = row_groups.shape[0] - 1
    if (matrix.nnz < analysis_gates.PAID_MIN_ENTRIES or n + matrix.nnz <= SMALL
            or matrix.indices.dtype != np.int32
            or matrix.indptr.dtype != np.int32 or max(n, matrix.nnz) >= 2**31 - 1
            or component_walks(matrix.nnz, n) is not None):
        return None
    kernels = _kernels()
    if kernels is None:
        return None
    k = seeds.shape[1]
    columns = kernels.seed_columns(seeds if extra is None else np.column_stack([seeds, extra]))
    groups = np.asarray(row_groups)
    if groups.flags.writeable:  # one signature: the product's row groups are read-only
        groups = groups.view()
        groups.flags.writeable = False
    n_comp, label, both, crowd, ptr, succ = kernels.components_reach(
        matrix.indptr, matrix.indices, groups, columns)
    del columns
    size = n + int(succ.size)
    if size <= SMALL:  # walked in plain Python by SciPy's route: its numbering
        return None
    reach = both if extra is None else np.ascontiguousarray(both[:, :k])
    reached = None if extra is None else np.ascontiguousarray(both[:, k])
    del both
    if not crowd.size:  # crowded's empty answer, in its type
        crowd = np.zeros(0, dtype=np.int64)
    n_comp = int(n_comp)
    # SciPy's route keeps int64 labels where it condenses (few components: the levels are
    # walked, so the state graph is kept for them here, unless the compiled pass finds
    # them from the matrix and the int32 labels), else its int32 and no graph
    few = 2 * n_comp < n
    comp = label.astype(np.int64) if few else label.astype(index_dtype(n), copy=False)
    compiled = warm(LEVELS)
    held = [(ptr, succ)] if few and not compiled else []
    labels = [label] if compiled else []
    del ptr, succ, label

    def later() -> np.ndarray:  # the walk levels() makes, on the same components
        if labels:
            level, ok = kernels.component_levels(matrix.indptr, matrix.indices, groups,
                                                 labels.pop(), n_comp)
            if ok:
                return level
        graph = sp.csr_array((np.ones(held[0][1].size, dtype=bool), held[0][1], held[0][0]),
                             shape=(n, n)) if held else graph_view(matrix, row_groups)
        held.clear()
        _, c, out_degree, preds_of = condensation(graph, n_comp, comp)
        del graph
        return leveled(size, n_comp, c, out_degree, preds_of, None).level

    return Levels(comp, None, None, later), reach, reached, crowd  # type: ignore[arg-type]
