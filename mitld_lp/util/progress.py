"""Progress bars that cost nothing when nobody sees them.

``tqdm.auto`` imports tqdm, asyncio and the e-mail parser (about 12 ms at start-up); a
run whose bar is off (a pipe, a benchmark, ``progress=False``) never imports it.
"""

from __future__ import annotations

import sys
from typing import Any, Protocol

__all__ = ["Bar", "bar"]


class Bar(Protocol):
    def update(self, n: float = 1) -> Any: ...

    def close(self) -> None: ...


class _Off:
    """The bar nobody sees."""

    def update(self, n: float = 1) -> None:
        pass

    def close(self) -> None:
        pass


def bar(shown: bool | None, **options: Any) -> Bar:
    """A tqdm bar with ``options`` if ``shown``, else a bar that does nothing.  None:
    tqdm's own rule for ``disable=None``, a bar in a notebook (its widget) or where
    standard error is a terminal, none in a pipe."""
    if shown is None:
        shown = "ipykernel" in sys.modules or bool(sys.stderr and sys.stderr.isatty())
    if not shown:
        return _Off()
    from tqdm.auto import tqdm

    return tqdm(**options)
