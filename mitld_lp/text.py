"""Text shown to people: messages stay one line of printable characters."""

from __future__ import annotations

__all__ = ["printable"]


def printable(text: str) -> str:
    """``text`` with every character a terminal would act on (newlines, escapes, NUL,
    unassigned code points) written as its Python escape, so that a name a user wrote
    can neither break a message over lines nor drive the terminal."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
