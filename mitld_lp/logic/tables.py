"""The formula parser, loaded from stored LALR tables instead of built at every start.

Building the LALR(1) parser from ``grammar.lark`` takes about 35 ms of CPU, a tenth of
solving the bundled case study from the command line.  ``_lalr_tables.py`` beside this
file holds the built parser as a Python literal (compiled to bytecode like any module),
with the SHA-256 of the grammar and the options, and the lark version that wrote it.
:func:`parser` loads it when both still match and builds from the grammar otherwise, so
an edited grammar or another lark release is never parsed with stale tables, only more
slowly.  After editing the grammar, regenerate the tables with::

    python -c "import mitld_lp.logic.tables as t; t.write()"

(``tests/test_parser_tables.py`` fails until then, and checks that the stored parser
reads every test formula as the grammar does.)
"""

from __future__ import annotations

import hashlib
import importlib.resources
from functools import cache
from pathlib import Path
from types import ModuleType

import lark
from lark import Lark
from lark.grammar import Rule
from lark.lexer import TerminalDef

__all__ = ["OPTIONS", "grammar", "grammar_digest", "parser", "stored", "write"]

#: The parser's options, part of the digest: changing one invalidates the tables.
OPTIONS: dict[str, object] = dict(
    parser="lalr",
    lexer="basic",
    start=["start", "dist_start"],
    maybe_placeholders=True,
    propagate_positions=True,
)


@cache
def grammar() -> str:
    return (
        importlib.resources.files("mitld_lp.logic")
        .joinpath("grammar.lark")
        .read_text(encoding="utf-8")
    )


def grammar_digest() -> str:
    """The SHA-256 of the grammar and :data:`OPTIONS`."""
    return hashlib.sha256(f"{grammar()}\n{sorted(OPTIONS.items())!r}".encode()).hexdigest()


def stored() -> ModuleType | None:
    """The stored tables' module if they were written from this grammar by this lark."""
    try:
        from mitld_lp.logic import _lalr_tables as tables
    except ImportError:
        return None
    if tables.GRAMMAR_SHA256 != grammar_digest() or tables.LARK_VERSION != lark.__version__:
        return None
    return tables


@cache
def parser() -> Lark:
    """The formula parser: from the stored tables when they are current (see above)."""
    tables = stored()
    if tables is not None:
        return Lark.load({"data": tables.DATA, "memo": tables.MEMO})
    return Lark(grammar(), **OPTIONS)


def write(path: Path | None = None) -> None:
    """Build the parser from the grammar and write its tables to ``path`` (default:
    ``_lalr_tables.py`` beside this file)."""
    path = path if path is not None else Path(__file__).with_name("_lalr_tables.py")
    data, memo = Lark(grammar(), **OPTIONS).memo_serialize([TerminalDef, Rule])
    path.write_text(
        '"""LALR tables of ``grammar.lark``, written by :func:`mitld_lp.logic.tables.write`;\n'
        'do not edit (see :mod:`mitld_lp.logic.tables`)."""\n'
        "# ruff: noqa: E501\n\n"
        f"GRAMMAR_SHA256 = {grammar_digest()!r}\n"
        f"LARK_VERSION = {lark.__version__!r}\n"
        f"DATA = {data!r}\n"
        f"MEMO = {memo!r}\n",
        encoding="utf-8",
    )
