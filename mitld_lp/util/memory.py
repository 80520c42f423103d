"""Memory budgets, shared by every stage that builds something big (a world from
another tool, the product, the exact stage) and by the surfaces that set them: the
default budget (:func:`default_max_memory`), a size written for people
(:func:`byte_text`; a size read from text such as ``"4G"`` is
:func:`mitld_lp.defaults.parse_size`, the one rule of every surface), and the
error of a build that would pass a budget (:class:`ProductTooLarge`).  Imports the
standard library only."""

from __future__ import annotations

import os

__all__ = ["ProductTooLarge", "default_max_memory", "byte_text"]


class ProductTooLarge(RuntimeError):
    """The product would exceed a budget (``max_states`` or ``max_memory``); a user
    error: the message names the numbers and what to change."""


def default_max_memory() -> int:
    """Half the machine's physical memory, in bytes (8 GiB if the system cannot say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
    except (AttributeError, ValueError, OSError):
        return 8 << 30


def byte_text(n: float, digits: int = 1) -> str:
    """``n`` bytes for people: ``"1.5 GB"``, ``"12.0 kB"`` (decimal units), ``"80 bytes"``."""
    for unit, size in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= size:
            return f"{n / size:.{digits}f} {unit}"
    return f"{n:.0f} bytes"
