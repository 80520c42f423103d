"""The bounds a compiled block had before its sweeps, held through them for the early
jump (:mod:`mitld_lp.solvers.early_jump`), packed where they allow it.

The first pass of the interval iteration sweeps each block from the bounds it was given
(a lower bound of +0.0, an upper one of +0.0 or 1.0): a byte an entry holds them to the
bit, not eight.  QVBS ``zeroconf`` 1000-4's block of nearly all its quotient's states
held them at 3.8 bytes a transition beside the sweeps' own arrays, at the iteration's
traced peak.  Any other bounds (the second pass, with the relative precision) are held
as they are.  Unpacked only for a jump that is taken, to the same bits."""

from __future__ import annotations

import numpy as np

from mitld_lp.solvers.kernels import take_rows

__all__ = ["FirstBounds"]

_ONE = np.float64(1.0).view(np.uint64)


class FirstBounds:
    """``bounds[states]`` (a float64 copy) as taken now: as ``uint8`` where every entry
    is +0.0 or 1.0 bitwise (so -0.0 is kept as it is), else the float64 copy."""

    __slots__ = ("_held", "_packed")

    def __init__(self, bounds: np.ndarray, states: np.ndarray) -> None:
        rows = take_rows(bounds, states)
        bits = rows.view(np.uint64)
        zero = bits == 0
        one = bits == _ONE
        np.logical_or(zero, one, out=zero)
        del bits
        self._packed = bool(zero.all())
        del zero
        if self._packed:
            self._held = one.view(np.uint8)
            del rows
        else:
            self._held = rows
            del one

    @property
    def packed(self) -> bool:
        """Whether the bounds are held a byte an entry."""
        return self._packed

    @property
    def nbytes(self) -> int:
        """The bytes held."""
        return int(self._held.nbytes)

    def values(self) -> np.ndarray:
        """The bounds as taken (float64, the same bits; a new array where packed)."""
        if self._packed:
            return self._held.astype(np.float64)
        return self._held
