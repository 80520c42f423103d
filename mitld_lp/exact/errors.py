"""The ways an exact answer stops: a model it cannot take (:class:`ExactError`, a user
error), a budget (:class:`ExactTooLarge`), the time limit (:class:`TimeUp`).  Kept apart
from the work so that the command line names them without importing it."""

from __future__ import annotations

from mitld_lp.product.budget import ProductTooLarge

__all__ = ["ExactError", "ExactTooLarge", "TimeUp"]


class ExactError(ValueError):
    """An exact answer cannot be given for this model as posed (the message says why):
    a user error, exit 2 on the command line."""


class ExactTooLarge(ProductTooLarge):
    """An exact answer would pass its budget (a budget stop, exit 3 on the command
    line); the message names the numbers."""


class TimeUp(Exception):
    """The time limit passed during the exact answer."""
