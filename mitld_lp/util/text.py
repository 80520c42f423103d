"""Text shown to people: messages stay one line of printable characters."""

from __future__ import annotations

__all__ = ["printable", "excerpt"]


def printable(text: str) -> str:
    """``text`` with every character a terminal would act on (newlines, escapes, NUL,
    unassigned code points) written as its Python escape, so that a name a user wrote
    can neither break a message over lines nor drive the terminal."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def excerpt(text: str, limit: int = 80) -> str:
    """``text`` itself when it has at most ``limit`` characters, else its start and its
    end around `` ... `` (``limit`` characters in all), so that a message quoting what a
    user wrote (a law of 100,000 masses, a 400-digit number) stays a short line."""
    if len(text) <= limit:
        return text
    tail = max((limit - 5) // 3, 1)
    head = max(limit - 5 - tail, 1)
    return f"{text[:head]} ... {text[-tail:]}"
