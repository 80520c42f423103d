"""SciPy's compiled sparse routines, imported in one place.

``scipy.sparse._sparsetools`` holds the C++ loops scipy.sparse's own methods call
(``csr_matvec``, ``csr_tocsc``, ``csr_row_index``, ...). It is private to SciPy, so
its import is guarded here once: :data:`sparsetools` is the module, or ``None`` on a
SciPy without it, where each caller takes its NumPy route instead.
"""
from __future__ import annotations

try:
    from scipy.sparse import _sparsetools as sparsetools
except ImportError:  # pragma: no cover - a SciPy without it: the callers' NumPy routes
    sparsetools = None

__all__ = ["sparsetools"]
