"""The Weibull law (and the exponential, its shape 1) in closed form, without
``scipy.stats`` (:func:`mitld_lp.distributions.families.weibull` and ``exponential``).

:class:`WeibullX` answers what :class:`~mitld_lp.distributions.scipy_laws.Discretised`
asks of a frozen ``scipy.stats.weibull_min(shape, scale=scale)`` at floats ``x >= 0``:
with ``y = (x / scale) ** shape``, ``sf = exp(-y)``, ``cdf = -expm1(-y)`` and
``logsf = -y``, SciPy's own formulas; NumPy's ``expm1`` may differ from SciPy's in the
last bit of the cdf (``tests/test_start_lean.py`` holds them to a relative 1e-13).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["WeibullX"]


class WeibullX:
    """``X`` with survival ``exp(-(x/scale)^shape)`` on ``[0, inf)``, ``shape`` and
    ``scale`` positive and finite."""

    __slots__ = ("shape", "scale")

    def __init__(self, shape: float, scale: float) -> None:
        self.shape = float(shape)
        self.scale = float(scale)

    def __repr__(self) -> str:
        return f"WeibullX({self.shape!r}, {self.scale!r})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (WeibullX, (self.shape, self.scale))

    def _y(self, x: Any) -> np.ndarray:
        xs = np.maximum(np.asarray(x, dtype=np.float64), 0.0)  # no mass below 0
        with np.errstate(over="ignore"):
            return np.power(xs / self.scale, self.shape)

    def cdf(self, x: Any) -> np.ndarray:
        return -np.expm1(-self._y(x))

    def sf(self, x: Any) -> np.ndarray:
        return np.exp(-self._y(x))

    def logsf(self, x: Any) -> np.ndarray:
        return -self._y(x)
