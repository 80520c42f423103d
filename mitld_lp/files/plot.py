"""The old name of :mod:`mitld_lp.plot`, kept for scripts that import it.

Pictures read results and sweeps, so they stand above them (``mitld_lp/plot.py``);
``files/`` is below every stage and imports none of them.  This alias loads
:mod:`mitld_lp.plot` on first use of one of its names (PEP 562) and is imported by
nothing in the package.
"""

from __future__ import annotations

import importlib
from typing import Any


def __getattr__(name: str) -> Any:
    if name.startswith("__"):
        raise AttributeError(name)
    return getattr(importlib.import_module("mitld_lp.plot"), name)
