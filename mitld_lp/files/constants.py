"""Named constants of a model file, substituted into its specification.

A model file may hold a ``[constants]`` table, ``name -> value`` (an integer, a float, a
boolean or a string), and write ``{name}`` in its ``spec``; each ``{name}`` is replaced
by the value's text before the formula is read::

    spec = "D[mu] b & F(b & F[0,{T}] A)"
    [constants]
    T = 3                       # the spec read is "D[mu] b & F(b & F[0,3] A)"

so that a deadline (or any other piece of the formula) has a key path,
``constants.T``, that a sweep can vary.  Braces are not part of the formula language,
so ``{`` always starts a constant.  Every ``{name}`` must be defined and every constant
used (nothing in a model file is silently ignored).
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["substitute", "constant_text"]

_USE = re.compile(r"\{([^{}]*)\}")
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def constant_text(value: Any) -> str | None:
    """The text a constant's value stands for in a formula: an integer as written,
    a float by its shortest round-trip form, ``true``/``false``, a string as it is;
    ``None`` for any other type."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | str):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    return None


def substitute(
    spec: str,
    constants: Mapping[str, Any],
    error: Callable[[str, str], Exception],
) -> str:
    """``spec`` with every ``{name}`` replaced by ``constant_text(constants[name])``.

    ``error(key_path, message)`` builds the exception raised for: a constant whose name
    a spec cannot write or whose value has no text (``constants.NAME``), a ``{...}``
    naming no constant or a lone brace (``spec``, with the column), and a constant the
    spec does not use (``constants.NAME``)."""
    texts: dict[str, str] = {}
    for name, value in constants.items():
        if not _NAME.fullmatch(name):
            raise error(f"constants.{json.dumps(name)}",
                        "a constant's name must be letters, digits and _ (not starting "
                        "with a digit)")
        text = constant_text(value)
        if text is None:
            raise error(f"constants.{name}", f"must be a number, a boolean or a string, "
                        f"got {type(value).__name__} {value!r}")
        texts[name] = text
    used: set[str] = set()

    def replace(m: re.Match[str]) -> str:
        name = m.group(1).strip()
        if name not in texts:
            known = ", ".join(sorted(texts)) or "none"
            raise error("spec", f"{_place(spec, m.start())}: {{{m.group(1)}}} names no constant "
                        f"under [constants] (defined: {known})")
        used.add(name)
        return texts[name]

    matched = [m.span() for m in _USE.finditer(spec)]
    for i, c in enumerate(spec):
        if c in "{}" and not any(a <= i < b for a, b in matched):
            raise error("spec", f"{_place(spec, i)}: a lone {c!r}: write a constant as "
                        "{name}")
    out = _USE.sub(replace, spec)
    for name in texts:
        if name not in used:
            raise error(f"constants.{name}", f"defined but not used by spec (it has no "
                        f"{{{name}}})")
    return out


def _place(text: str, index: int) -> str:
    """``line:column`` (1-based) of ``text[index]``."""
    before = text[:index]
    return f"{before.count(chr(10)) + 1}:{index - (before.rfind(chr(10)) + 1) + 1}"
