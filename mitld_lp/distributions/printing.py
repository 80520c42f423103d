"""How a law is written: the text of a literal ``family(arg, ...)``, shared by the
formula printer (``str`` of a ``D[...]``) and the labels of built laws, so that a law's
label is the literal that :func:`mitld_lp.logic.parse` reads back."""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import TypeAlias

import numpy as np

__all__ = ["DistArg", "format_arg", "literal_text", "int_text"]

#: An argument of a literal as written: a number, or a name (``scipy(nbinom, 3, 0.5)``).
DistArg: TypeAlias = int | float | str


def _digits(n: int) -> int:
    """The number of decimal digits of ``|n|``, without printing it (``str`` refuses
    integers of more than ``sys.get_int_max_str_digits()`` digits)."""
    n = abs(n)
    if n < 10:
        return 1
    d = int(n.bit_length() * math.log10(2)) + 1
    return d if n >= 10 ** (d - 1) else d - 1


def int_text(n: int) -> str:
    """An integer as a message quotes it: in full up to 30 digits, else by its length
    (``an integer of 401 digits``)."""
    if -(10**30) < n < 10**30:
        return str(n)
    return f"{'a negative' if n < 0 else 'an'} integer of {_digits(n)} digits"


def format_arg(a: object) -> str:
    """One argument as the parser reads it back: an integral float keeps its ``.0``
    (``3.0`` is a float, ``3`` an int); numpy scalars print as Python numbers.  An
    integer too long for ``str`` (no family accepts one; only Python code can make it)
    is written ``<an integer of N digits>``."""
    if isinstance(a, np.integer):
        a = int(a)
    elif isinstance(a, np.floating):
        a = float(a)
    if isinstance(a, str):
        return a
    if isinstance(a, float):
        if math.isfinite(a) and a == int(a) and abs(a) < 1e16:
            return f"{int(a)}.0"
        return repr(a)
    if isinstance(a, int):
        try:
            return str(a)
        except ValueError:
            return f"<{int_text(a)}>"
    return str(a)


def literal_text(family: str, args: Iterable[object]) -> str:
    """``family(arg, ...)``, e.g. ``geometric(0.3)`` or ``scipy(nbinom, 3, 0.5)``."""
    return f"{family}({', '.join(format_arg(a) for a in args)})"
