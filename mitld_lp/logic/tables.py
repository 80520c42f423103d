"""The formula parser, loaded from stored LALR tables instead of built at every start.

Building the LALR(1) parser from ``grammar.lark`` takes about 35 ms of CPU, a tenth of
solving the bundled case study from the command line.  ``lalr_tables.json`` beside this
file holds the built parser (lark's own serialisation, 1.5 ms to read), with the text of
the grammar and the options it was built from (:func:`grammar_key`; their SHA-256 too,
for people), and the lark version that wrote it.  :func:`parser` loads it when the text
and the version still match and builds from the grammar otherwise, so an edited grammar
or another lark release is never parsed with stale tables, only more slowly.  The text
is compared as it is, not through its SHA-256: the comparison is exact, and the command
line's process does not import ``hashlib`` (OpenSSL's start, 4 ms of CPU) for it.
After editing the grammar, regenerate the tables with::

    python -c "import mitld_lp.logic.tables as t; t.write()"

(``tests/test_parser_tables.py`` fails until then, and checks that the stored parser
reads every test formula as the grammar does.)
"""

from __future__ import annotations

import json
import logging
from functools import cache
from pathlib import Path
from typing import Any

# lark is imported where a parser is loaded or written: a formula the plain parser
# (mitld_lp.logic.plain_parse) reads never needs it
TYPE_CHECKING = False
if TYPE_CHECKING:
    from lark import Lark

__all__ = ["OPTIONS", "TABLES", "grammar", "grammar_digest", "grammar_key", "parser", "stored",
           "write"]

log = logging.getLogger(__name__)

#: The stored tables' file, beside this module.
TABLES = "lalr_tables.json"

#: The parser's options, part of the digest: changing one invalidates the tables.
OPTIONS: dict[str, object] = dict(
    parser="lalr",
    lexer="basic",
    start=["start", "dist_start"],
    maybe_placeholders=True,
    propagate_positions=True,
)


def _beside(name: str) -> str:
    """The text of the package file ``name`` beside this module: read from the folder
    (0.05 ms of CPU), or through :mod:`importlib.resources` where the package is not a
    folder of files (a zip), whose first use in a process costs 2.5 ms, about a
    hundredth of the bundled case's command."""
    try:
        return Path(__file__).with_name(name).read_text(encoding="utf-8")
    except OSError:
        import importlib.resources

        return importlib.resources.files("mitld_lp.logic").joinpath(name).read_text(
            encoding="utf-8")


@cache
def grammar() -> str:
    return _beside("grammar.lark")


def grammar_key() -> str:
    """The grammar and :data:`OPTIONS` as one text: what the stored tables were built
    from."""
    return f"{grammar()}\n{sorted(OPTIONS.items())!r}"


def grammar_digest() -> str:
    """The SHA-256 of :func:`grammar_key`."""
    import hashlib

    return hashlib.sha256(grammar_key().encode()).hexdigest()


def _int_keys(pairs: list[tuple[str, Any]]) -> dict[Any, Any]:
    """JSON's keys are strings: lark's tables number their states and memo entries."""
    return {int(k) if k.isdigit() else k: v for k, v in pairs}


def stored() -> dict[str, Any] | None:
    """The stored tables if they were written from this grammar by this lark."""
    try:
        text = _beside(TABLES)
    except FileNotFoundError:
        return None
    import lark

    tables = json.loads(text, object_pairs_hook=_int_keys)
    if (tables.get("grammar_key") != grammar_key()
            or tables.get("lark_version") != lark.__version__):
        return None
    return tables


@cache
def parser() -> Lark:
    """The formula parser: from the stored tables when they are current (see above); a
    file that cannot be read as tables (damaged in packaging) is logged and the parser
    built from the grammar."""
    from lark import Lark
    from lark.exceptions import LarkError

    try:
        tables = stored()
        if tables is not None:
            return Lark.load({"data": tables["data"], "memo": tables["memo"]})
    except (ValueError, KeyError, TypeError, AttributeError, AssertionError,
            LarkError) as err:  # lark checks its tables with assert
        log.warning("parser tables %s unusable (%s: %s); building the parser from the "
                    "grammar", TABLES, type(err).__name__, err)
    return Lark(grammar(), **OPTIONS)


def write(path: Path | None = None) -> None:
    """Build the parser from the grammar and write its tables to ``path`` (default:
    :data:`TABLES` beside this file)."""
    import lark
    from lark import Lark
    from lark.grammar import Rule
    from lark.lexer import TerminalDef

    path = path if path is not None else Path(__file__).with_name(TABLES)
    data, memo = Lark(grammar(), **OPTIONS).memo_serialize([TerminalDef, Rule])
    tables = {"grammar_sha256": grammar_digest(), "grammar_key": grammar_key(),
              "lark_version": lark.__version__, "data": data, "memo": memo}
    path.write_text(json.dumps(tables, separators=(",", ":")) + "\n", encoding="utf-8")
