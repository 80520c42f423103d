"""A number as it was written, and the rational number it stands for.

A probability written ``0.1`` in a model file or a formula is the rational ``1/10``; the
float ``0.1`` that the solvers compute with is ``3602879701896397 / 2**55``.  The exact
answer (:mod:`mitld_lp.exact`) is about the model as written, so the readers of text
(the model file's TOML reader, the formula parser) keep the text of every decimal
beside its float: a :class:`Written` is a float (every other stage computes with it as
with any float) that remembers the characters it was read from.

:func:`exact_value` is the one rule from a number to the rational it stands for:

* a :class:`Written` number: its text, read as a decimal (``0.10000000000000001`` is
  ``10000000000000001 / 10**17``, not the float it rounds to);
* an ``int`` or a :class:`fractions.Fraction`: itself;
* a float made in Python (``GridWorld(slip=0.1)``): the shortest decimal that rounds to
  it, Python's ``repr`` -- the literal the program was written with whenever that had at
  most 15 significant digits.  This is the rule stormpy applies to a float constant of
  a PRISM program (``instantiate_constants``), so a constant means the same to Storm's
  exact engine and to this package.
"""

from __future__ import annotations

import math
from decimal import Decimal
from fractions import Fraction
from numbers import Rational
from typing import Any

import numpy as np

__all__ = ["Written", "exact_value"]


class Written(float):
    """A float read from text, with the text (``text``): ``Written("0.1") == 0.1``, and
    ``exact_value(Written("0.1")) == Fraction(1, 10)``.  Arithmetic on it gives plain
    floats; it pickles as its text."""

    __slots__ = ("text",)

    text: str

    def __new__(cls, text: str) -> Written:
        self = super().__new__(cls, text)
        self.text = text
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        return (Written, (self.text,))


def exact_value(x: object) -> Fraction:
    """The rational number ``x`` stands for (module docs).  Raises ``ValueError`` for a
    value that is not a finite number (a bool is not a number here)."""
    if isinstance(x, bool | np.bool_):
        raise ValueError(f"{x!r} is not a number")
    if isinstance(x, Written):
        return Fraction(x.text.replace("_", ""))  # TOML allows 1_000.5
    if isinstance(x, Rational | np.integer):
        return Fraction(int(x.numerator), int(x.denominator)) if isinstance(x, Rational) \
            else Fraction(int(x))
    if isinstance(x, Decimal):
        if not x.is_finite():
            raise ValueError(f"{x!r} is not a finite number")
        return Fraction(x)
    if isinstance(x, float | np.floating):
        if not math.isfinite(float(x)):
            raise ValueError(f"{x!r} is not a finite number")
        return Fraction(repr(float(x)))
    raise ValueError(f"{x!r} is not a number")
