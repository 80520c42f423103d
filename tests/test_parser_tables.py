"""The stored LALR tables (``mitld_lp/logic/lalr_tables.json``) are the grammar's:
written from the current ``grammar.lark``, and the parser loaded from them reads every
formula -- trees, positions, errors -- as a parser built from the grammar does."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import lark
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lark import Lark
from lark.exceptions import UnexpectedInput

from mitld_lp.logic import tables
from mitld_lp.testing.hypothesis import formulas

ROOT = Path(__file__).resolve().parent.parent
#: The file as stored, read as the package reads it, whatever its digest and lark version.
FILE = json.loads((ROOT / "mitld_lp" / "logic" / tables.TABLES).read_text(encoding="utf-8"),
                  object_pairs_hook=tables._int_keys)

#: Both parsers, built once: the one from the grammar is what the tables replace.
STORED = Lark.load({"data": FILE["data"], "memo": FILE["memo"]})
BUILT = Lark(tables.grammar(), **tables.OPTIONS)

WRONG = ["F[0,3 a", "a &", "D[mu] (a & b)", "F[3,1] a", "a U U b", "((a)", "G[0,] a",
         "D[geometric(0.5) a", "a $ b", "F<=x a", "X", "", "a\n& &\nb", "F[0,3]\n  a |"]


def _reading(parser: Lark, text: str, start: str = "start") -> object:
    """What ``parser`` makes of ``text``: every subtree with its rule and span, or the
    error's kind and place."""
    try:
        tree = parser.parse(text, start=start)
    except UnexpectedInput as err:
        return type(err).__name__, err.line, err.column
    return [(t.data, t.children, getattr(t.meta, "line", None),
             getattr(t.meta, "column", None), getattr(t.meta, "end_column", None))
            for t in tree.iter_subtrees()]


def test_the_tables_were_written_from_this_grammar():
    assert FILE["grammar_sha256"] == tables.grammar_digest(), (
        "grammar.lark or the parser's options changed: regenerate the tables with "
        'python -c "import mitld_lp.logic.tables as t; t.write()"')
    # the text the package compares is the text digested, the grammar file's own
    assert FILE["grammar_key"] == tables.grammar_key()
    assert FILE["grammar_key"].startswith(
        (ROOT / "mitld_lp" / "logic" / "grammar.lark").read_text(encoding="utf-8"))


def _model_specs() -> list[str]:
    specs = []
    for path in sorted((ROOT / "models").glob("*.toml")):
        spec = tomllib.loads(path.read_text(encoding="utf-8")).get("spec")
        if isinstance(spec, str):
            specs.append(spec)
    return specs


@pytest.mark.parametrize("text", _model_specs() + WRONG)
def test_stored_and_built_parsers_read_alike(text):
    assert _reading(STORED, text) == _reading(BUILT, text)


@pytest.mark.parametrize("text", ["geometric(0.5)", "mu", "uniform(1, 4", "poisson(2.5)"])
def test_stored_and_built_parsers_read_distributions_alike(text):
    assert _reading(STORED, text, "dist_start") == _reading(BUILT, text, "dist_start")


@settings(max_examples=60, deadline=None)
@given(formula=formulas(with_dist=True), cut=st.integers(min_value=0, max_value=200))
def test_stored_and_built_parsers_read_generated_formulas_alike(formula, cut):
    text = str(formula)
    assert _reading(STORED, text) == _reading(BUILT, text)
    # and the prefixes, which are mostly wrong: the errors agree too
    assert _reading(STORED, text[:cut]) == _reading(BUILT, text[:cut])


@pytest.mark.skipif(FILE["lark_version"] != lark.__version__,
                    reason="the tables were written by another lark release")
def test_the_parser_in_use_is_the_stored_one():
    assert tables.stored() == FILE


@pytest.mark.parametrize("stale", ["grammar", "options"])
def test_stale_tables_are_not_used(monkeypatch, stale):
    if stale == "grammar":  # one character more in the grammar's text
        monkeypatch.setattr(tables, "grammar", lambda: tables._beside("grammar.lark") + " ")
    else:
        monkeypatch.setattr(tables, "OPTIONS", dict(tables.OPTIONS, maybe_placeholders=False))
    assert tables.stored() is None
    tables.parser.cache_clear()
    try:
        fresh = tables.parser()  # built from the grammar
        assert _reading(fresh, "F[0,3] a") == _reading(BUILT, "F[0,3] a")
    finally:
        tables.parser.cache_clear()


@pytest.mark.parametrize("damage", [
    "missing", {"data": {}, "memo": {}}, {"data": {"x": 1}, "memo": {0: {}}}, "not json"])
def test_missing_or_damaged_tables_are_built_from_the_grammar(monkeypatch, caplog, damage):
    if damage == "missing":
        monkeypatch.setattr(tables, "TABLES", "no_such_tables.json")
        assert tables.stored() is None
    elif damage == "not json":
        def unreadable():
            raise json.JSONDecodeError("Expecting value", "", 0)
        monkeypatch.setattr(tables, "stored", unreadable)
    else:
        monkeypatch.setattr(tables, "stored", lambda: damage)
    tables.parser.cache_clear()
    try:
        fresh = tables.parser()
        for text in ["F[0,3] a", "D[mu] b & G !c", "a U[1,2]"]:
            assert _reading(fresh, text) == _reading(BUILT, text)
    finally:
        tables.parser.cache_clear()
    if damage != "missing":
        assert "unusable" in caplog.text


def test_the_files_are_read_through_importlib_resources_where_not_in_a_folder(monkeypatch):
    # the package's folder is read directly; a package that is not one (a zip) is read
    # through importlib.resources: the same grammar and tables, the same parser
    folder = ROOT / "mitld_lp" / "logic"
    monkeypatch.setattr(tables, "__file__", str(ROOT / "no_such_folder" / "tables.py"))
    tables.grammar.cache_clear()
    try:
        assert tables.grammar() == (folder / "grammar.lark").read_text(encoding="utf-8")
        assert tables.stored() == FILE
    finally:
        tables.grammar.cache_clear()
