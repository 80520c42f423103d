"""One certification check, the record every route's certificate is made of."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Check", "close"]


@dataclass(frozen=True, slots=True)
class Check:
    """One certification check: what was compared, whether it passed, the numbers."""

    name: str
    passed: bool
    detail: str


def close(name: str, a: float, b: float, tol: float) -> Check:
    """The check that ``a`` and ``b`` are finite and within ``tol`` of each other."""
    ok = bool(np.isfinite(a) and np.isfinite(b) and abs(a - b) <= tol)
    return Check(name, ok, f"{a:.10g} vs {b:.10g} (|diff| = {abs(a - b):.2e}, tol {tol:g})")
