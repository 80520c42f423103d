"""The command line's argument types: each parses the text of one option and returns
its value, or raises :class:`argparse.ArgumentTypeError` with the reason (argparse names
the option; the command prints one line and exits 2)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from mitld_lp import defaults

__all__ = ["probability_budget", "bounded_int", "memory_size", "seconds", "solver_name",
           "bands_reading"]


def probability_budget(text: str) -> float:
    """An ``--epsilon``: a number strictly between 0 and 1 (:func:`defaults.check_epsilon`)."""
    try:
        return defaults.check_epsilon(float(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a number in (0, 1), got {text!r}") from None


def bounded_int(low: int, high: int | None = None) -> Callable[[str], int]:
    """An integer in ``low..high`` (``high`` None: no upper bound)."""

    def parse_int(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if value < low or (high is not None and value > high):
            bound = f">= {low:,}" if high is None else f"in {low:,}..{high:,}"
            raise argparse.ArgumentTypeError(f"must be an integer {bound}, got {text}")
        return value

    parse_int.__name__ = "integer"
    return parse_int


def memory_size(text: str) -> int:
    """A byte count with an optional binary unit (:func:`mitld_lp.defaults.parse_size`)."""
    try:
        return defaults.parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def seconds(text: str) -> float:
    """A positive, finite number of seconds (``--time-limit``,
    :func:`mitld_lp.defaults.check_seconds`)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, got {text!r}") from None
    try:
        return defaults.check_seconds(value, repr(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def solver_name(text: str) -> str:
    """An LP solver name, in any case; checked against cvxpy's installed solvers."""
    name = text.strip().upper()
    if name == defaults.SOLVER:  # the default needs no cvxpy import to be checked
        return name
    import cvxpy

    installed = cvxpy.installed_solvers()
    if name not in installed:
        raise argparse.ArgumentTypeError(
            f"unknown or not installed LP solver {text!r} (installed: {', '.join(installed)})"
        )
    return name


def bands_reading(text: str) -> str:
    """How a band is read, ``worst`` or ``best`` (``--bands``,
    :func:`mitld_lp.defaults.check_bands`)."""
    try:
        return defaults.check_bands(text, repr(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
