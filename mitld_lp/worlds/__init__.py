"""Worlds from other tools, as :class:`mitld_lp.worlds.game.Game` values.

* :mod:`mitld_lp.worlds.prism`: a PRISM MDP, built by Storm (``pip install -e '.[prism]'``);
* :mod:`mitld_lp.worlds.gym`: a gymnasium toy-text transition table ``env.unwrapped.P``
  (gymnasium itself is not needed).

This package imports no optional dependency: ``stormpy`` is imported only when a PRISM
file is loaded, so ``import mitld_lp.worlds.prism`` works without it.
"""

from __future__ import annotations

__all__ = ["WorldError"]


class WorldError(ValueError):
    """A world from another tool cannot be turned into a game; the message names the
    input (file, label, action, state) at fault."""
