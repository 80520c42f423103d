"""Progress bars on a terminal, and nowhere else; they cost nothing when nobody sees them.

One rule for every long stage (the product, the information-state product, interval
iteration, the block LPs, rollouts, sweeps, batches): :func:`bar` with ``shown``

* ``None`` (the default everywhere): a bar where standard error is a terminal, or in a
  notebook (tqdm's widget); none in a pipe or a file;
* ``False``: none; ``True``: a bar wherever standard error goes;

and none at all inside :func:`silenced` (the command line's ``-q`` and ``--json``, a
sweep's points), whatever ``shown`` says.  A bar appears only once its stage has run
:data:`DELAY` seconds, so a quick run draws nothing, and it is erased when its stage
ends.  Bars are tqdm's (a dependency already; ``rich`` would add one, and its live
display would have to own the terminal the command's own lines are printed on).

``tqdm.auto`` imports tqdm, asyncio and the e-mail parser (about 12 ms at start-up); a
run whose bar is off (a pipe, a benchmark, ``progress=False``) never imports it.
Lines printed while a bar is drawn go through :func:`write`, which clears the bars
first and draws them again after, so a line is never mixed into a bar; what it writes
is the line itself, byte for byte.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any, Protocol, TextIO, TypeVar

__all__ = ["Bar", "bar", "tracked", "silenced", "write", "abandon", "DELAY"]

T = TypeVar("T")

DELAY = 0.5
"""Seconds a stage runs before its bar is drawn."""

_SILENCED: ContextVar[bool] = ContextVar("mitld_lp_progress_silenced", default=False)


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
    """A tqdm bar with ``options`` (``delay`` :data:`DELAY` unless given) where it is
    shown (module docs), else a bar that does nothing."""
    if shown is False or _SILENCED.get():
        return _Off()
    if shown is None:
        shown = "ipykernel" in sys.modules or bool(sys.stderr and sys.stderr.isatty())
    if not shown:
        return _Off()
    from tqdm.auto import tqdm

    return tqdm(**{"delay": DELAY, **options})


def tracked(items: Iterable[T], shown: bool | None, size: Callable[[T], float] | None = None,
            **options: Any) -> Iterator[T]:
    """``items``, each counted on a bar (:func:`bar`: ``shown`` and ``options``) once
    the loop has done it, ``size(item)`` (default 1) at a time; the bar is closed when
    the loop ends (the command line erases a bar left by an error, :func:`abandon`)."""
    shown_bar = bar(shown, **options)
    try:
        for item in items:
            yield item
            shown_bar.update(1 if size is None else size(item))
    finally:
        shown_bar.close()


@contextmanager
def silenced(quiet: bool = True) -> Iterator[None]:
    """No bar inside this block (in this thread and the context it runs in) when
    ``quiet``."""
    token = _SILENCED.set(quiet or _SILENCED.get())
    try:
        yield
    finally:
        _SILENCED.reset(token)


def write(text: str, file: TextIO) -> None:
    """``text`` and a newline on ``file``; the bars drawn are cleared first and drawn
    again after (nothing else reaches ``file``; a bar not drawn yet stays hidden)."""
    auto = sys.modules.get("tqdm.auto")
    drawn = [] if auto is None else [b for b in list(getattr(auto.tqdm, "_instances", ()))
                                     if _drawn(b)]
    if not drawn:
        file.write(text + "\n")
        return
    with auto.tqdm.get_lock():
        for b in drawn:
            b.clear(nolock=True)
        file.write(text + "\n")
        file.flush()
        for b in drawn:
            b.refresh(nolock=True)


def _drawn(shown: Any) -> bool:
    """Whether tqdm has drawn this bar (its ``delay`` passed) and not closed it."""
    return (not getattr(shown, "disable", True) and hasattr(shown, "start_t")
            and shown.last_print_t >= shown.start_t + shown.delay)


def abandon() -> None:
    """Erase every bar and draw none of them again: the command is stopped (Ctrl-C, its
    time limit) while its thread may still be running."""
    auto = sys.modules.get("tqdm.auto")
    if auto is None:
        return
    with auto.tqdm.get_lock():
        for shown in list(getattr(auto.tqdm, "_instances", ())):
            if not shown.disable:
                shown.clear(nolock=True)
                shown.disable = True
