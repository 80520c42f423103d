"""Memory budgets, shared by every stage that builds something big (a world from
another tool, the product, the exact stage) and by the surfaces that set them: the
default budget (:func:`default_max_memory`), a size written for people
(:func:`byte_text`) or read from text such as ``"4G"`` (:func:`memory_size`, the
command line's ``--max-memory`` and a model file's ``[budgets] max_memory``), and the
error of a build that would pass a budget (:class:`ProductTooLarge`).  Imports the
standard library only."""

from __future__ import annotations

import argparse
import os

__all__ = ["ProductTooLarge", "default_max_memory", "byte_text", "memory_size",
           "MAX_MEMORY_SIZE"]


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


_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40, "P": 1 << 50,
          "E": 1 << 60}

MAX_MEMORY_SIZE = (1 << 63) - 1
"""The largest size accepted (8E less a byte): a byte count is a signed 64-bit integer
to the operating system, and no machine comes near it."""


def memory_size(text: str) -> int:
    """A byte count with an optional binary unit: ``500M``, ``4G``, ``1.5G``, ``2P``
    (``K M G T P E``, each 1024 times the last; a trailing ``B`` or ``iB`` is allowed).
    A fault raises :class:`argparse.ArgumentTypeError` with the reason (the command
    line's option type; a model file's reader names the key path)."""
    body = text.strip().upper().removesuffix("B").removesuffix("I")
    unit = body[-1:] if body[-1:] in _UNITS and body[-1:] else ""
    try:
        number = float(body[: len(body) - len(unit)])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a size such as 4G or 500M, got {text!r}") from None
    if not number == number or number in (float("inf"), float("-inf")):  # nan, inf
        raise argparse.ArgumentTypeError(f"must be a finite size, got {text!r}")
    value = number * _UNITS[unit]
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive size (at least 1 byte), got "
                                         f"{text!r}")
    if value > MAX_MEMORY_SIZE:
        raise argparse.ArgumentTypeError(f"must be below 8E (2^63 bytes), got {text!r}")
    return int(value)
