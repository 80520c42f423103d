"""The families of laws: how each is named, its parameters validated and the law built.

Families (all over the steps 1, 2, ...):

* ``geometric(p)``: ``mu(k) = (1-p)^(k-1) p``, ``p in (0, 1]``; ``h(k) = p``.
* ``pmf(m1, m2, ...)``: ``mu(k) = m_k``; masses ``>= 0`` summing to at most 1.
* ``uniform(a, b)``: ``mu(k) = 1/(b-a+1)`` for ``a <= k <= b``; ``h(k) = 1/(b-k+1)`` there.
* ``poisson(lam)``: ``K = 1 + X``, ``X ~ Poisson(lam)``.
* ``scipy_discrete(name, *args)``: any ``scipy.stats`` discrete distribution; ``K = 1 + X``
  if its support starts at 0, ``K = X`` if it starts at 1 or later.
* ``discretised(name, *args)``, ``exponential(rate)``, ``weibull(shape, scale)``,
  ``gamma(shape, scale)``: a continuous ``X >= 0`` with cdf ``F`` read at whole steps,
  ``K = ceil(X)``: ``mu(k) = F(k) - F(k-1)``.

Every numeric parameter must be a finite float (an integer beyond the float range, a nan
or an infinity is a :class:`DistributionError`, never an ``OverflowError``).
:data:`FAMILIES` is the one table of them that the parser, the model loader and
:mod:`.literal` consult.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
import numpy.typing as npt

from mitld_lp.distributions.law import (
    MASS_TOLERANCE,
    MAX_STEP,
    MAX_TABLE_STEPS,
    DistributionError,
    FirstOccurrence,
)
from mitld_lp.distributions.printing import int_text, literal_text

__all__ = [
    "geometric",
    "pmf",
    "poisson",
    "uniform",
    "scipy_discrete",
    "discretised",
    "exponential",
    "weibull",
    "gamma",
    "Family",
    "FAMILIES",
]


# --------------------------------------------------------------------------- parameters


def _label(family: str, *args: Any) -> str:
    return literal_text(family, args)


def _is_number(x: object) -> bool:
    return isinstance(x, int | float | np.integer | np.floating) and not isinstance(
        x, bool | np.bool_
    )


def _real(where: str, name: str, x: Any) -> float:
    if not _is_number(x):
        raise DistributionError(where, f"{name} must be a number, got {x!r}")
    try:
        return float(x)
    except OverflowError:  # an int beyond the largest float (about 1.8e308)
        raise DistributionError(
            where,
            f"{name} is beyond the float range (at most about 1.8e308), got {int_text(int(x))}",
        ) from None


def _positive(where: str, name: str, x: object) -> float:
    v = _real(where, name, x)
    if not (math.isfinite(v) and v > 0):
        raise DistributionError(where, f"{name} must be a finite number > 0, got {v!r}")
    return v


def _integer(where: str, name: str, x: object) -> int:
    v = _real(where, name, x)
    if isinstance(x, int | np.integer):
        return int(x)  # exactly: through a float, 2**62 + 1 would become 2**62
    if not (math.isfinite(v) and v == math.floor(v)):
        raise DistributionError(where, f"{name} must be an integer, got {x!r}")
    return int(v)


def _scipy_args(label: str, args: Sequence[object]) -> list[float]:
    out = []
    for i, a in enumerate(args, start=1):
        v = _real(label, f"argument {i}", a)
        if not math.isfinite(v):
            raise DistributionError(label, f"argument {i} must be a finite number, got {v!r}")
        out.append(v)
    return out


# --------------------------------------------------------------------------- constructors


def geometric(p: float) -> FirstOccurrence:
    """``P(K = k) = (1-p)^(k-1) p`` for ``k >= 1``, ``p in (0, 1]``: probability ``p`` at
    every step (hazard ``p``), the memoryless case of the paper's case study."""
    label = _label("geometric", p)
    pf = _real(label, "p", p)
    if not 0 < pf <= 1:
        raise DistributionError(label, "p must be in (0, 1]")
    from mitld_lp.distributions.closed import Geometric  # read once a law is built

    return Geometric(label, pf, written=p)


def pmf(masses: Sequence[float] | npt.NDArray[Any]) -> FirstOccurrence:
    """``P(K = k) = masses[k-1]`` for ``k = 1..n``; ``never = 1 - sum(masses)``.

    Masses must be finite and ``>= 0`` with sum ``<= 1``; a sum within ``MASS_TOLERANCE``
    of 1 is treated as exactly 1 (the masses are rescaled, no never-mass).  At most
    :data:`MAX_TABLE_STEPS` masses (checked before the table is made).
    """
    count = masses.size if isinstance(masses, np.ndarray) else len(masses)
    if count > MAX_TABLE_STEPS:
        raise DistributionError(
            f"pmf(... {count} masses)",
            f"has {count} masses; a table is limited to MAX_TABLE_STEPS = {MAX_TABLE_STEPS} "
            "steps",
        )
    values = np.asarray(masses).ravel().tolist() if isinstance(masses, np.ndarray) else list(masses)
    label = _label("pmf", *values)
    if not values:
        raise DistributionError(
            label, "needs at least one mass (for an event that never happens write pmf(0))"
        )
    m = np.empty(len(values))
    for i, x in enumerate(values, start=1):
        v = _real(label, f"mass m{i} (step {i})", x)
        if math.isnan(v) or math.isinf(v):
            raise DistributionError(label, f"mass m{i} (step {i}) must be finite, got {v!r}")
        if v < 0:
            raise DistributionError(label, f"mass m{i} (step {i}) is negative: {v!r}")
        m[i - 1] = v
    try:
        total = math.fsum(m.tolist())
    except OverflowError:  # finite masses whose exact sum is beyond the largest float
        raise DistributionError(label, "masses sum to more than the largest float > 1") from None
    if total > 1 + MASS_TOLERANCE:
        raise DistributionError(label, f"masses sum to {total:.12g} > 1")
    from mitld_lp.distributions.closed import Finite

    return Finite(label, m, written=("masses", tuple(values)))


def uniform(a: int, b: int) -> FirstOccurrence:
    """Equally likely on the steps ``a..b`` inclusive, ``1 <= a <= b <= MAX_STEP``:
    ``P(K = k) = 1/(b-a+1)``, hazard ``1/(b-k+1)`` for ``a <= k <= b``.

    Up to :data:`MAX_TABLE_STEPS` steps it is a table like :func:`pmf`; beyond, the
    closed forms (no per-step memory)."""
    label = _label("uniform", a, b)
    lo = _integer(label, "a", a)
    hi = _integer(label, "b", b)
    if lo < 1:
        raise DistributionError(
            label, f"a must be >= 1 (step 0 is not allowed), got {int_text(lo)}"
        )
    if hi > MAX_STEP:
        raise DistributionError(
            label, f"b = {int_text(hi)} is beyond the last step 2**62 = {MAX_STEP}"
        )
    if hi < lo:
        raise DistributionError(label, f"b must be >= a = {int_text(lo)}, got {int_text(hi)}")
    from mitld_lp.distributions.closed import Finite, Uniform

    if hi > MAX_TABLE_STEPS:
        return Uniform(label, lo, hi)
    m = np.zeros(hi)
    m[lo - 1 :] = 1.0 / (hi - lo + 1)
    return Finite(label, m, written=("uniform", (lo, hi)))


def poisson(lam: float) -> FirstOccurrence:
    """``K = 1 + X`` with ``X ~ Poisson(lam)``, ``lam > 0``:
    ``P(K = k) = exp(-lam) lam^(k-1) / (k-1)!``."""
    label = _label("poisson", lam)
    lf = _positive(label, "lam", lam)
    from mitld_lp.distributions import scipy_laws  # the adapter; scipy.stats not imported
    from mitld_lp.distributions.poisson_law import PoissonX  # closed form, no scipy.stats

    # a Poisson pmf is log-concave (mu(k+1)/mu(k) = lam/k decreases), so its hazard
    # increases (towards 1): FirstOccurrence.hazard_range_from
    law = scipy_laws.ShiftedDiscrete(label, PoissonX(lf), math.inf, shift=1, increasing=True)
    return scipy_laws.evaluable(law, "poisson")


def scipy_discrete(name: str, *args: float) -> FirstOccurrence:
    """Any ``scipy.stats`` discrete distribution ``X`` (shape arguments, then ``loc``):
    ``K = 1 + X`` if its support starts at 0, ``K = X`` if it starts at 1 or later
    (e.g. ``geom``).  A support reaching below 0 is an error."""
    label = _label("scipy", name, *args)
    from mitld_lp.distributions import scipy_laws

    gen = scipy_laws.generator(label, name)
    if not isinstance(gen, scipy_laws.stats().rv_discrete):
        raise DistributionError(label, f"scipy.stats.{name} is continuous, not discrete")
    return scipy_laws.shifted(label, name, gen, _scipy_args(label, args))


def discretised(name: str, *args: float) -> FirstOccurrence:
    """A ``scipy.stats`` continuous distribution ``X`` with support in ``[0, inf)`` (shape
    arguments, then ``loc``, ``scale``) read at whole steps: ``K = ceil(X)``,
    ``P(K = k) = F(k) - F(k-1)``."""
    label = _label("scipy", name, *args)
    from mitld_lp.distributions import scipy_laws

    gen = scipy_laws.generator(label, name)
    if not isinstance(gen, scipy_laws.stats().rv_continuous):
        raise DistributionError(label, f"scipy.stats.{name} is discrete, not continuous")
    return scipy_laws.discretised(label, name, gen, _scipy_args(label, args), {})


def exponential(rate: float) -> FirstOccurrence:
    """Discretised ``Exp(rate)``: ``P(K = k) = e^(-rate (k-1)) (1 - e^(-rate))``, i.e.
    ``geometric(1 - exp(-rate))``."""
    label = _label("exponential", rate)
    r = _positive(label, "rate", rate)
    return _weibull_form(label, "expon", 1.0, 1.0 / r)


def weibull(shape: float, scale: float) -> FirstOccurrence:
    """Discretised Weibull: ``S(k) = exp(-(k/scale)^shape)``; shape 1 is geometric."""
    label = _label("weibull", shape, scale)
    c = _positive(label, "shape", shape)
    s = _positive(label, "scale", scale)
    return _weibull_form(label, "weibull_min", c, s)


def _weibull_form(label: str, name: str, shape: float, scale: float) -> FirstOccurrence:
    """``K = ceil(X)`` for ``X`` with survival ``exp(-(x/scale)^shape)``, in closed form
    (SciPy's ``name`` by the same formulas, without importing ``scipy.stats``)."""
    from mitld_lp.distributions import scipy_laws
    from mitld_lp.distributions.weibull_law import WeibullX

    return scipy_laws.evaluable(scipy_laws.Discretised(label, WeibullX(shape, scale), math.inf),
                                name)


def gamma(shape: float, scale: float) -> FirstOccurrence:
    """Discretised Gamma(shape, scale): ``P(K = k) = F(k) - F(k-1)``; shape 1 is
    ``exponential(1/scale)``."""
    label = _label("gamma", shape, scale)
    a = _positive(label, "shape", shape)
    s = _positive(label, "scale", scale)
    from mitld_lp.distributions import scipy_laws

    return scipy_laws.discretised(label, "gamma", scipy_laws.stats().gamma, [a], {"scale": s})


# --------------------------------------------------------------------------- the registry


@dataclass(frozen=True, slots=True)
class Family:
    """One family of laws: how it is written and how it is built.  :data:`FAMILIES` is
    the one table that the parser (shapes of ``D[family(args)]``), the model loader
    (``{ family = value }``, :func:`~.literal.from_table`) and the formula literal
    (:class:`~.literal.DistLiteral`) consult.

    Attributes:
        name: the family name as written.
        params: the names of its numeric parameters, in order; for a variadic family the
            numbers are any count of at least ``len(params)``.
        build: the constructor, called with the arguments as written; it validates the
            values and raises :class:`DistributionError`.
        description: the law in one line, for messages and documentation.
        variadic: any number of numbers (pmf masses, scipy shape arguments).
        named: the first argument is a name, not a number (``scipy(nbinom, 3, 0.5)``).
        integers: the numbers must be integers (``uniform``).
    """

    name: str
    params: tuple[str, ...]
    build: Callable[..., FirstOccurrence]
    description: str
    variadic: bool = False
    named: bool = False
    integers: bool = False

    @property
    def min_numbers(self) -> int:
        return len(self.params)

    @property
    def max_numbers(self) -> int | None:
        return None if self.variadic else len(self.params)

    @property
    def takes_list(self) -> bool:
        """Whether a model file writes its arguments as a list (one number otherwise)."""
        return self.variadic or self.named or len(self.params) != 1

    def shape(self) -> str:
        """How a literal of this family is written, e.g. ``uniform(a, b)``."""
        parts = ["name"] if self.named else []
        parts += list(self.params)
        if self.variadic:
            parts.append("...")
        return f"{self.name}({', '.join(parts)})"

    def arity_error(self, n_args: int) -> str | None:
        """Why ``n_args`` arguments do not fit this family (None when they do)."""
        if self.named and n_args == 0:
            return f"{self.name} needs a distribution name, e.g. {self.name}(nbinom, 3, 0.5)"
        n = n_args - int(self.named)
        hi = self.max_numbers
        if n >= self.min_numbers and (hi is None or n <= hi):
            return None
        s = "s" if self.min_numbers != 1 else ""
        at_least = "at least " if hi is None else ""
        return (f"{self.name} takes {at_least}{self.min_numbers} argument{s} "
                f"({', '.join(self.params)}), got {n_args}")


def _build_scipy(name: object, *args: Any) -> FirstOccurrence:
    from mitld_lp.distributions import scipy_laws

    gen = scipy_laws.generator(_label("scipy", name, *args), name)
    assert isinstance(name, str)  # generator() checked it
    if isinstance(gen, scipy_laws.stats().rv_discrete):
        return scipy_discrete(name, *args)
    return discretised(name, *args)


#: Every family, by name (in the order the documentation lists them).
FAMILIES: Mapping[str, Family] = MappingProxyType({
    f.name: f
    for f in (
        Family("geometric", ("p",), geometric,
               "P(K = k) = (1-p)^(k-1) p, p in (0, 1]; hazard p (memoryless)"),
        Family("pmf", ("m1",), lambda *m: pmf(m),
               "P(K = k) = m_k for k = 1..n; masses >= 0 summing to at most 1 (the rest: "
               "never)", variadic=True),
        Family("poisson", ("lam",), poisson, "K = 1 + X, X ~ Poisson(lam), lam > 0"),
        Family("uniform", ("a", "b"), uniform,
               "equally likely on the steps a..b, 1 <= a <= b; hazard 1/(b-k+1)",
               integers=True),
        Family("exponential", ("rate",), exponential,
               "K = ceil(X), X ~ Exp(rate), rate > 0 (geometric(1 - exp(-rate)))"),
        Family("weibull", ("shape", "scale"), weibull,
               "K = ceil(X), S(k) = exp(-(k/scale)^shape), shape, scale > 0"),
        Family("gamma", ("shape", "scale"), gamma,
               "K = ceil(X), X ~ Gamma(shape, scale), shape, scale > 0"),
        Family("scipy", (), _build_scipy,
               "any scipy.stats law: discrete K = X (+1 if its support starts at 0), "
               "continuous K = ceil(X)", variadic=True, named=True),
    )
})


def build(family: str, args: Sequence[Any], where: str) -> FirstOccurrence:
    """Look ``family`` up in :data:`FAMILIES` and build it from ``args``; unknown
    families and arity errors are reported at ``where``."""
    fam = FAMILIES.get(family)
    if fam is None:
        raise DistributionError(
            where,
            f"unknown distribution family {family!r}; expected one of {', '.join(FAMILIES)}",
        )
    why = fam.arity_error(len(args))
    if why is not None:
        raise DistributionError(where, why)
    return fam.build(*args)
