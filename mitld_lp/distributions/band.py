"""Laws known only within a band: the per-step hazard may be anything inside an interval
``[h_lo(k), h_hi(k)]``, chosen at every step by an adversary (docs/semantics.md).

A band keeps a *nominal* law (the fitted point law, or the centre of an interval), whose
pmf, survival, hazard and samples it answers with, so that everything that needs one law
(simulation, printing) has one; the solvers read :meth:`~.law.FirstOccurrence.hazard_band`
and :meth:`~.law.FirstOccurrence.survival_upper` instead.

Three shapes of band:

* :class:`ConstantBand`: ``h(k) in [lo, hi]`` at every step (``geometric([0.2, 0.4])``, a
  fitted geometric or exponential law); memoryless, no clock, exact.
* :class:`TableBand`: a band ``S_lo(k) <= S(k) <= S_hi(k)`` on the survival function given
  as a table for ``k = 0..n`` and constant beyond (Kaplan-Meier with a simultaneous band).
* :class:`EnvelopeBand`: finitely many laws of one family (``poisson([2, 3])``, the
  likelihood region of a fitted family): ``h(k)`` between the least and the greatest of
  their hazards at step ``k``.

A survival band with no family behind it (:class:`TableBand`) gives per-step hazard
bands conservatively: every law whose survival lies in the band has
``h(k) = 1 - S(k)/S(k-1)`` inside::

    h_lo(k) = clip(1 - S_hi(k) / S_lo(k-1), 0, 1),  h_hi(k) = clip(1 - S_lo(k) / S_hi(k-1), 0, 1)

(``h_lo = 0`` where ``S_lo(k-1) = 0``; ``h = 1`` where ``S_hi(k-1) = 0``: the step cannot
be reached, the convention of :mod:`.law`).  The adversary may combine these hazards in
ways no single law of the band does, so a guarantee under the hazard band holds for every
law of the survival band.  A truncation point is the first ``T`` with ``S_hi(T) <= eps``.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mitld_lp.distributions.families import build
from mitld_lp.distributions.law import (
    MAX_HAZARD_SCAN,
    MAX_STEP,
    DistributionError,
    FirstOccurrence,
    FloatArray,
    IntArray,
    Steps,
    scalar_or_array,
    step_array,
)
from mitld_lp.distributions.printing import literal_text

__all__ = ["Band", "ConstantBand", "TableBand", "EnvelopeBand", "band_of_laws",
           "hazard_band_from_survival", "last_event_step", "UnboundedBand", "TailLaw",
           "TailBand", "needs_tail", "tail_step", "tail_intervals", "tail_bands"]


class UnboundedBand(DistributionError):
    """A band with no truncation point: its upper survival never comes within the
    truncation's share (its laws' never masses differ and its hazard may stay positive
    for ever); the routes bound its tail instead (:func:`tail_bands`)."""


def hazard_band_from_survival(
    s_lo_prev: FloatArray, s_hi_prev: FloatArray, s_lo: FloatArray, s_hi: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The per-step hazard band of a survival band (module docstring): ``S(k-1)`` in
    ``[s_lo_prev, s_hi_prev]`` and ``S(k)`` in ``[s_lo, s_hi]`` give
    ``h(k) in [1 - s_hi / s_lo_prev, 1 - s_lo / s_hi_prev]`` clipped to ``[0, 1]``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(s_lo_prev > 0, 1.0 - s_hi / s_lo_prev, 0.0)
        hi = np.where(s_hi_prev > 0, 1.0 - s_lo / s_hi_prev, 1.0)
    lo = np.clip(lo, 0.0, 1.0)
    hi = np.clip(hi, 0.0, 1.0)
    lo = np.where(s_hi_prev > 0, lo, 1.0)  # unreachable step: h = 1 by convention
    return np.minimum(lo, hi), hi


@dataclass(frozen=True, slots=True, eq=False)
class Band(FirstOccurrence):
    """A law known only within a band (module docstring); its point answers are those of
    ``nominal``."""

    nominal: FirstOccurrence

    # ------------------------------------------------------------ the band's hooks
    @abstractmethod
    def _band_pos(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        """``(h_lo(k), h_hi(k))`` for steps ``k >= 1``."""

    @abstractmethod
    def _sf_hi_pos(self, k: IntArray) -> FloatArray:
        """``S_hi(k)`` for steps ``k >= 1``."""

    @abstractmethod
    def _band_constant_from(self) -> int | None:
        """The first step from which ``h_lo`` and ``h_hi`` are both constant (None: never)."""

    # ------------------------------------------------------------ the nominal law
    def _pmf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.nominal.pmf(k), dtype=np.float64)

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.nominal.cdf(k), dtype=np.float64)

    def _sf_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.nominal.survival(k), dtype=np.float64)

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        return np.asarray(self.nominal.hazard(k), dtype=np.float64)

    def _never(self) -> float:
        return self.nominal.never

    def _last_step(self) -> float:
        return math.inf

    def _constant_hazard_from(self) -> int | None:
        """Both the nominal hazard and the band are constant from this step on (the clock
        the STA keeps serves both)."""
        a, b = self.nominal.constant_hazard_from, self._band_constant_from()
        return None if a is None or b is None else max(a, b)

    def _sample_from(self, v: FloatArray) -> FloatArray:
        return self.nominal._sample_from(v)

    # ------------------------------------------------------------ the band
    @property
    def is_ambiguous(self) -> bool:
        return True

    def hazard_band(self, k: Steps) -> tuple[Any, Any]:
        """``(h_lo(k), h_hi(k))``, both 0 for ``k <= 0`` (no event at step 0)."""
        ks, scalar = step_array(k)
        lo = np.zeros(ks.shape)
        hi = np.zeros(ks.shape)
        pos = ks >= 1
        if pos.any():
            lo[pos], hi[pos] = self._band_pos(ks[pos])
        return scalar_or_array(lo, scalar), scalar_or_array(hi, scalar)

    def survival_upper(self, k: Steps) -> Any:
        """``S_hi(k)``, 1 for ``k <= 0``."""
        ks, scalar = step_array(k)
        out = np.ones(ks.shape)
        pos = ks >= 1
        if pos.any():
            out[pos] = self._sf_hi_pos(ks[pos])
        return scalar_or_array(out, scalar)

    def truncation_point(self, eps: float) -> int:
        """The smallest ``T >= 0`` with ``S_hi(T) <= eps`` (every law of the band has
        survived past ``T`` with probability at most ``eps``)."""
        e = float(eps)
        if not e >= 0:
            raise DistributionError(self.label, f"truncation eps must be >= 0, got {eps!r}")
        if e >= 1.0:
            return 0
        lo, hi = 0, 1  # invariant: S_hi(lo) > eps
        while float(self.survival_upper(hi)) > e:
            if hi >= MAX_STEP:
                raise UnboundedBand(
                    self.label,
                    f"the band's upper survival is still above eps = {e:.6g} at step 2**62 "
                    "(the band allows an event that never happens)",
                )
            lo, hi = hi, 2 * hi
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if float(self.survival_upper(mid)) <= e:
                hi = mid
            else:
                lo = mid
        return hi

    def hazard_bounds_from(self, k: int) -> tuple[float, float, float, float]:
        """Sound bounds on the band's hazard interval over the steps ``j >= k``:
        ``(a, b, c, d)`` with ``a <= inf h_lo``, ``sup h_lo <= b``, ``c <= inf h_hi`` and
        ``sup h_hi <= d``; exact from the step where the band is constant (its
        intervals over ``k..max(k, c0)``), else ``(0, 1, 0, 1)``."""
        k = max(int(k), 1)
        c = self._band_constant_from()
        if c is None or max(k, c) - k > MAX_HAZARD_SCAN:
            return 0.0, 1.0, 0.0, 1.0
        lo, hi = self.hazard_band(np.arange(k, max(k, c) + 1, dtype=np.int64))
        return float(lo.min()), float(lo.max()), float(hi.min()), float(hi.max())


@dataclass(frozen=True, slots=True, eq=False)
class ConstantBand(Band):
    """``h(k) in [lo, hi]`` at every step ``k >= 1``: ``S_hi(k) = (1 - lo)^k``."""

    lo: float
    hi: float

    def _band_pos(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        return np.full(k.shape, self.lo), np.full(k.shape, self.hi)

    def _sf_hi_pos(self, k: IntArray) -> FloatArray:
        if self.lo >= 1.0:
            return np.zeros(k.shape)
        return np.exp(k * math.log1p(-self.lo))

    def _band_constant_from(self) -> int | None:
        return 1


@dataclass(frozen=True, slots=True, eq=False)
class TableBand(Band):
    """A survival band as tables ``s_lo[k], s_hi[k]`` for ``k = 0..n`` (``s[0] = 1``),
    constant beyond ``n``."""

    s_lo: FloatArray = field(repr=False)
    s_hi: FloatArray = field(repr=False)

    def __post_init__(self) -> None:
        lo = np.array(self.s_lo, dtype=np.float64)
        hi = np.array(self.s_hi, dtype=np.float64)
        if lo.shape != hi.shape or lo.ndim != 1 or lo.size < 1:
            raise ValueError("TableBand: s_lo and s_hi must be 1-D tables of one length")
        if not (np.all(lo >= 0) and np.all(lo <= hi) and np.all(hi <= 1)):
            raise ValueError("TableBand: need 0 <= s_lo <= s_hi <= 1")
        lo[0] = hi[0] = 1.0
        lo.setflags(write=False)
        hi.setflags(write=False)
        object.__setattr__(self, "s_lo", lo)
        object.__setattr__(self, "s_hi", hi)

    def _at(self, table: FloatArray, k: IntArray) -> FloatArray:
        return table[np.minimum(k, table.size - 1)]

    def _band_pos(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        return hazard_band_from_survival(
            self._at(self.s_lo, k - 1), self._at(self.s_hi, k - 1),
            self._at(self.s_lo, k), self._at(self.s_hi, k),
        )

    def _sf_hi_pos(self, k: IntArray) -> FloatArray:
        return self._at(self.s_hi, k)

    def _band_constant_from(self) -> int | None:
        return int(self.s_lo.size)  # S(k-1) and S(k) both past the table from k = n + 1


@dataclass(frozen=True, slots=True, eq=False)
class EnvelopeBand(Band):
    """The laws of a parametric family between ``laws`` (the ends of a parameter
    interval, points of a likelihood region's boundary): at step ``k`` the hazard may be
    anything between the least and the greatest of their hazards,
    ``[min_j h_j(k), max_j h_j(k)]``, and ``S_hi(k) = max_j S_j(k)``.  For a family whose
    hazard is monotone in its parameter (geometric, poisson, exponential: larger
    parameter, stochastically smaller in the hazard-rate order) the two ends bound every
    law between; the adversary may still change hazards from step to step, so this band
    contains every law of the family and more."""

    laws: tuple[FirstOccurrence, ...]

    def _each(self, k: IntArray, what: str) -> FloatArray:
        return np.vstack([np.asarray(getattr(law, what)(k), dtype=np.float64)
                          for law in self.laws])

    def _band_pos(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        h = self._each(k, "hazard")
        return h.min(axis=0), h.max(axis=0)

    def _sf_hi_pos(self, k: IntArray) -> FloatArray:
        return self._each(k, "survival").max(axis=0)

    def _band_constant_from(self) -> int | None:
        """The step from which every law's hazard is constant (a table of masses: 0 past
        its support, whatever mass it leaves to never), so the least and the greatest of
        them are too: the clock stops there and nothing is truncated, where laws whose
        never masses differ have no truncation point (:meth:`truncation_point`).  None
        where some law's hazard never settles (a Poisson law)."""
        starts = [law.constant_hazard_from for law in self.laws]
        return None if any(k is None for k in starts) else max(starts)  # type: ignore[type-var]

    def hazard_bounds_from(self, k: int) -> tuple[float, float, float, float]:
        """:meth:`Band.hazard_bounds_from` from each law's hazard range over ``j >= k``
        (:meth:`~.law.FirstOccurrence.hazard_range_from`, ``(i_j, s_j)``) where some
        law's hazard never settles: ``h_lo(j) = min_l h_l(j)`` lies in ``[min_l i_l,
        min_l s_l]`` and ``h_hi(j) = max_l h_l(j)`` in ``[max_l i_l, max_l s_l]``."""
        if self._band_constant_from() is not None:
            return Band.hazard_bounds_from(self, k)
        ranges = [law.hazard_range_from(k) for law in self.laws]
        inf, sup = [r[0] for r in ranges], [r[1] for r in ranges]
        return min(inf), min(sup), max(inf), max(sup)


def last_event_step(law: FirstOccurrence) -> int | None:
    """The last step at which a band's event can happen, where every hazard of the band
    is 0 from some step on (a band of tables of masses: each law's hazard is 0 past its
    support, whatever mass it leaves to never): past it neither a law of the band nor
    nature's choice of hazards has the event happen, so a truncation there cuts nothing,
    whatever never masses the laws keep (where they differ, no step has the band's
    upper survival within a share of the nominal never mass: no
    :meth:`~Band.truncation_point` serves).  None for a law known exactly or a band
    whose hazard may stay positive."""
    c = law.constant_hazard_from
    if not law.is_ambiguous or c is None:
        return None
    return max(c - 1, 0) if float(law.hazard_band(c)[1]) == 0.0 else None


def band_of_laws(
    label: str, nominal: FirstOccurrence, laws: Sequence[FirstOccurrence]
) -> FirstOccurrence:
    """The band spanned by ``laws`` (with ``nominal`` among the point answers): a
    :class:`ConstantBand` over their hazards when every one is memoryless (the exact band
    of a geometric or exponential family), else their :class:`EnvelopeBand`.  A band of
    one hazard is the nominal law itself (a point: nothing is ambiguous)."""
    every = (nominal, *laws)
    if all(law.is_memoryless for law in every):
        h = [float(law.hazard(1)) for law in every]
        if min(h) == max(h):
            return nominal
        return ConstantBand(label, nominal, min(h), max(h))
    return EnvelopeBand(label, nominal, tuple(every))


#: Families whose one parameter may be an interval: their survival is monotone in it, so
#: the laws at its two ends bound the survival of every law between.
INTERVAL_FAMILIES = ("geometric", "poisson", "exponential")


def interval(family: str, lo: object, hi: object, where: str) -> FirstOccurrence:
    """The band of ``family`` with its parameter anywhere in ``[lo, hi]``, e.g.
    ``geometric([0.2, 0.4])``: hazard in ``[0.2, 0.4]`` at every step (a geometric's
    lower end may be 0: the event may never come).  Its nominal law is the family at the
    middle of the interval.  Errors name ``where``."""
    if family not in INTERVAL_FAMILIES:
        raise DistributionError(
            where, f"an interval parameter is allowed for {', '.join(INTERVAL_FAMILIES)} "
            f"(one parameter, survival monotone in it), not {family}")
    if family == "geometric" and isinstance(lo, int | float) and lo == 0:
        # a hazard that may be 0: the event may never come (no law geometric(0) exists)
        ends = [build(family, [hi], where)]
        a, b = 0.0, float(hi)  # type: ignore[arg-type]
    else:
        ends = [build(family, [x], where) for x in (lo, hi)]  # validates both numbers
        a, b = float(lo), float(hi)  # type: ignore[arg-type]
    if not a <= b:
        raise DistributionError(where, f"the interval's lower end {lo!r} exceeds its upper "
                                f"end {hi!r}")
    label = literal_text(family, ([a, b],))
    nominal = build(family, [(a + b) / 2.0], where)
    if a == 0.0:
        return ConstantBand(label, nominal, 0.0, b)
    return band_of_laws(label, nominal, ends)


# --------------------------------------------------------------------------- the tail
# A band whose hazard may stay positive for ever while its laws' never masses differ
# has no truncation point (UnboundedBand): a cut at any step would lose the runs in
# which nature brings the event later.  Its tail is bounded instead: past a step K the
# band is replaced by a constant interval, once holding every interval of the band
# past K (the outer band: nature may do more than it can) and once lying within every
# one (the inner band: nature may do less).  Both are constant from K + 1, so the
# exact machinery solves them with nothing truncated, and for a robust maximum the
# outer band's policy guarantees its value there on the true band while the inner
# band's optimum bounds the true one from above (docs/robust.md).


@dataclass(frozen=True, slots=True, eq=False)
class TailLaw(FirstOccurrence):
    """``base``'s hazards up to ``step`` and ``rate`` at every step after: the nominal
    law of a :class:`TailBand`."""

    base: FirstOccurrence
    step: int
    rate: float

    def _survival_past(self, k: IntArray) -> FloatArray:
        """``S(k)`` for steps ``k > step``: ``S(step) (1 - rate)^(k - step)``."""
        s = float(self.base.survival(self.step))
        if self.rate >= 1.0:
            return np.zeros(k.shape)
        return s * np.exp((k - self.step) * math.log1p(-self.rate))

    def _sf_pos(self, k: IntArray) -> FloatArray:
        out = np.asarray(self.base.survival(np.minimum(k, self.step)), dtype=np.float64)
        past = k > self.step
        if past.any():
            out = np.array(out)
            out[past] = self._survival_past(k[past])
        return out

    def _cdf_pos(self, k: IntArray) -> FloatArray:
        return 1.0 - self._sf_pos(k)

    def _pmf_pos(self, k: IntArray) -> FloatArray:
        out = np.asarray(self.base.pmf(np.minimum(k, self.step)), dtype=np.float64)
        past = k > self.step
        if past.any():  # S(k - 1) rate
            out = np.array(out)
            out[past] = self.rate * np.asarray(self.survival(k[past] - 1), dtype=np.float64)
        return out

    def _hazard_pos(self, k: IntArray) -> FloatArray:
        out = np.full(k.shape, self.rate)
        head = k <= self.step
        if head.any():
            out[head] = self.base.hazard(k[head])
        return out

    def _never(self) -> float:
        return float(self.base.survival(self.step)) if self.rate == 0.0 else 0.0

    def _last_step(self) -> float:
        if self.rate > 0.0 and float(self.base.survival(self.step)) > 0.0:
            return math.inf
        return min(self.base._last_step(), float(self.step))

    def _constant_hazard_from(self) -> int | None:
        return self.step + 1


@dataclass(frozen=True, slots=True, eq=False)
class TailBand(Band):
    """``base``'s hazard intervals up to ``step`` and ``[lo, hi]`` at every step after
    (:func:`tail_bands`): constant from ``step + 1``, so nothing of it is truncated."""

    base: FirstOccurrence
    step: int
    lo: float
    hi: float

    def _band_pos(self, k: IntArray) -> tuple[FloatArray, FloatArray]:
        lo, hi = np.full(k.shape, self.lo), np.full(k.shape, self.hi)
        head = k <= self.step
        if head.any():
            lo[head], hi[head] = self.base.hazard_band(k[head])
        return lo, hi

    def _sf_hi_pos(self, k: IntArray) -> FloatArray:
        out = np.array(self.base.survival_upper(np.minimum(k, self.step)), dtype=np.float64)
        past = k > self.step
        if past.any():  # nature's least hazard at every step past it
            out[past] *= (np.exp((k[past] - self.step) * math.log1p(-self.lo))
                          if self.lo < 1.0 else 0.0)
        return out

    def _band_constant_from(self) -> int | None:
        return self.step + 1


def needs_tail(law: FirstOccurrence, eps: float) -> bool:
    """Whether ``law`` is a band that no truncation at ``eps`` serves
    (:class:`UnboundedBand`) and that is not constant from some step (which the clock
    solves exactly): its tail must be bounded (:func:`tail_bands`)."""
    if not law.is_ambiguous or law.constant_hazard_from is not None:
        return False
    try:
        law.truncation_point(eps)
    except UnboundedBand:
        return True
    return False


def _laws_of(band: FirstOccurrence) -> tuple[FirstOccurrence, ...]:
    return band.laws if isinstance(band, EnvelopeBand) else (band.nominal,)  # type: ignore[attr-defined]


def tail_step(band: FirstOccurrence, eps: float) -> int:
    """The step ``K`` past which :func:`tail_bands` bounds ``band``: the last at which
    a law of the band that surely happens (no never mass) has survived with
    probability more than ``eps`` (its truncation point), or at which a law's hazard
    still changes (its :attr:`~.law.FirstOccurrence.constant_hazard_from` less 1),
    and at least 1.  Past it the laws' hazard ranges are those of their tails (a table
    of masses past its support, a Poisson law's increasing hazard from there)."""
    K = 1
    for law in _laws_of(band):
        c = law.constant_hazard_from
        if c is not None:
            K = max(K, c - 1)
        if law.never <= eps and (c is None or law.never == 0.0):
            K = max(K, law.truncation_point(eps))
    return K


def tail_intervals(
    band: FirstOccurrence, step: int
) -> tuple[tuple[float, float], tuple[float, float] | None]:
    """The outer and inner intervals of ``band``'s hazards past ``step``
    (:meth:`Band.hazard_bounds_from` at ``step + 1``): the outer ``[inf h_lo, sup
    h_hi]`` holds every ``[h_lo(k), h_hi(k)]``, ``k > step``; the inner ``[sup h_lo,
    inf h_hi]`` lies within every one, None where no constant interval does."""
    if not isinstance(band, Band):
        raise TypeError(f"tail_intervals: {band} is not a band")
    a, b, c, d = band.hazard_bounds_from(step + 1)
    return (a, d), ((b, c) if b <= c else None)


def tail_bands(band: FirstOccurrence, step: int) -> tuple[TailBand, TailBand | None]:
    """``band`` with its hazards past ``step`` replaced by the constant outer interval
    and by the inner one (:func:`tail_intervals`; None where there is none): every law
    of ``band``, and every choice of nature's within it, is one of the outer band's,
    and every one of the inner band's is one of ``band``'s.  Their nominal laws keep
    the band's nominal hazards up to ``step`` and that of step ``step + 1`` clipped to
    the interval after."""
    assert isinstance(band, Band)
    outer, inner = tail_intervals(band, step)
    h = float(band.nominal.hazard(step + 1))

    def made(lo: float, hi: float) -> TailBand:
        nominal = TailLaw(band.nominal.label, band.nominal, step, min(max(h, lo), hi))
        return TailBand(band.label, nominal, band, step, lo, hi)

    return made(*outer), (None if inner is None else made(*inner))
