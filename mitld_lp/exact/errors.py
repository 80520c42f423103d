"""The ways an exact answer stops: a model it cannot take (:class:`ExactError`, a user
error), a budget (:class:`ExactTooLarge`), the time limit (:class:`TimeUp`).  Kept apart
from the work so that the command line names them without importing it; defined in
:mod:`mitld_lp.util.stops`, below the float brackets that raise them too."""

from __future__ import annotations

from mitld_lp.util.stops import ExactError, ExactTooLarge, TimeUp

__all__ = ["ExactError", "ExactTooLarge", "TimeUp"]
