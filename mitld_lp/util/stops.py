"""The ways an exact or bounded answer stops: a model it cannot take
(:class:`ExactError`, a user error), a budget (:class:`ExactTooLarge`), the time limit
(:class:`TimeUp`).  Below every stage that raises them (the exact answers and the float
brackets that take over past their budgets), so that neither imports the other for
them; :mod:`mitld_lp.exact.errors` is their public name.  Imports the standard library
and :mod:`mitld_lp.util.memory` only."""

from __future__ import annotations

from mitld_lp.util.memory import ProductTooLarge

__all__ = ["ExactError", "ExactTooLarge", "TimeUp"]


class ExactError(ValueError):
    """An exact answer cannot be given for this model as posed (the message says why):
    a user error, exit 2 on the command line."""


class ExactTooLarge(ProductTooLarge):
    """An exact answer would pass its budget (a budget stop, exit 3 on the command
    line); the message names the numbers."""


class TimeUp(Exception):
    """The time limit passed during the exact answer."""
