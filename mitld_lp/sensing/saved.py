"""``load_sensed``, where users found it: the sensed controller's file is now one kind of
the one controller file (:mod:`mitld_lp.controllers.format`), read by the one reader
(:mod:`mitld_lp.controllers.reader`); :func:`mitld_lp.load_controller` loads every kind."""

from __future__ import annotations

import os

from mitld_lp.controllers.kinds import SensedController

__all__ = ["load_sensed"]


def load_sensed(path: str | os.PathLike[str]) -> SensedController:
    """The controller that acts on sensor reports saved at ``path``
    (:meth:`SensedController.load <mitld_lp.controllers.kinds.PlanController.load>`)."""
    return SensedController.load(path)
