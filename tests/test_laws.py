"""Inline laws and reserved words: one registry of families, one set of reserved words,
laws validated where they are written (with the line and column), and parse errors that
say when a reserved word was hit."""

from __future__ import annotations

import ast
import importlib.resources
import pathlib
import re

import pytest

from mitld_lp import model as M
from mitld_lp.cli import main
from mitld_lp.distributions import FAMILIES, DistributionError, Family, from_spec, from_table
from mitld_lp.logic import check, parse
from mitld_lp.logic.fragment import FragmentError
from mitld_lp.logic.parser import ParseError, parse_distribution
from mitld_lp.logic.syntax import RESERVED, DistLiteral, Prop, dist
from mitld_lp.testing.hypothesis import KEYWORDS

# (formula, column of the law's family name, a word of the reason), from issue 12 item 4.
BAD_LAWS = [
    ("D[geometric(1.5)] a", 3, "p must be in (0, 1]"),
    ("D[geometric(0)] a", 3, "p must be in (0, 1]"),
    ("D[pmf(0.6, 0.6)] a", 3, "masses sum to 1.2 > 1"),
    ("D[pmf(-0.1, 0.5)] a", 3, "negative"),
    ("D[poisson(-1)] a", 3, "lam must be"),
    ("D[uniform(3, 1)] a", 3, "b must be >= a"),
    ("D[scipy(nonexistent, 1)] a", 3, "unknown scipy.stats distribution 'nonexistent'"),
    ("F[0,2] p & (q |\n  D[ geometric(2)] b)", 6, "p must be in (0, 1]"),
]


@pytest.mark.parametrize(("text", "column", "why"), BAD_LAWS)
def test_parse_validates_inline_laws_at_their_position(text: str, column: int, why: str) -> None:
    with pytest.raises(ParseError) as info:
        parse(text)
    err = info.value
    assert (err.line, err.column) == (text.count("\n") + 1, column)
    assert why in str(err)
    assert "\n" not in str(err)


@pytest.mark.parametrize(("text", "column", "why"), BAD_LAWS)
def test_cli_check_refuses_inline_laws_with_exit_2(
    text: str, column: int, why: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["check", text]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1
    assert f":{column}: " in err and why in err


def test_check_validates_laws_of_formulas_built_in_python() -> None:
    f = dist(DistLiteral("geometric", (1.5,)), Prop("a"))
    with pytest.raises(FragmentError, match=r"D\[geometric\(1\.5\)\] a has an invalid"):
        check(f)
    assert check(dist(DistLiteral("geometric", (0.5,)), Prop("a"))).events


def test_parse_distribution_validates_too() -> None:
    with pytest.raises(ParseError, match="p must be in"):
        parse_distribution("geometric(3)")


def test_one_registry_of_families() -> None:
    """Every family is a :class:`Family` whose arity the parser, :func:`from_spec` and
    :func:`from_table` all follow."""
    examples = {
        "geometric": (0.5,), "pmf": (0.25, 0.75), "poisson": (2.0,), "uniform": (2, 4),
        "exponential": (0.5,), "weibull": (1.5, 3.0), "gamma": (2.0, 1.5),
        "scipy": ("nbinom", 3, 0.5),
    }
    assert set(FAMILIES) == set(examples)
    for name, args in examples.items():
        fam = FAMILIES[name]
        assert isinstance(fam, Family) and fam.name == name and fam.description
        assert fam.arity_error(len(args)) is None
        law = from_spec(DistLiteral(name, args))
        text = str(DistLiteral(name, args))
        assert parse_distribution(text) == DistLiteral(name, args)
        value = list(args) if fam.takes_list else args[0]
        tabled = from_table({name: value}, "distributions.mu")
        assert tabled.label == law.label
        for k in (1, 2, 5):
            assert tabled.pmf(k) == pytest.approx(law.pmf(k), abs=1e-15)
        # one argument too many is refused by all three, unless the family is variadic
        more = (*args, 1)
        if fam.max_numbers is not None:
            assert fam.arity_error(len(more)) is not None
            with pytest.raises(ParseError):
                parse_distribution(str(DistLiteral(name, more)))
            with pytest.raises(DistributionError, match="takes"):
                from_spec(DistLiteral(name, more))


def _grammar_keywords() -> set[str]:
    text = importlib.resources.files("mitld_lp.logic").joinpath("grammar.lark").read_text()
    words = re.findall(r'^_?[A-Z_]+:\s*"([^"]+)"\s*$', text, flags=re.MULTILINE)
    return {w for w in words if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", w)}


def test_reserved_words_are_the_grammars_keywords() -> None:
    assert _grammar_keywords() == RESERVED
    assert KEYWORDS is RESERVED
    assert not hasattr(M, "_RESERVED")


@pytest.mark.parametrize("word", sorted(RESERVED))
def test_model_refuses_each_reserved_word_as_a_name(word: str) -> None:
    src = f'''
name = "r"
spec = "F[0,3] A"
[world]
type = "gridworld"
size = [2, 2]
start = [0, 0]
[world.regions]
A = [[1, 1]]
{word} = [[0, 1]]
'''
    with pytest.raises(M.ModelError, match="regions"):
        M.loads_model(src)


@pytest.mark.parametrize(
    ("text", "word"),
    [("F (D & E)", "D"), ("p & U", "U"), ("p & F", "F"), ("X & p", "X"), ("G | true", "G")],
)
def test_parse_error_names_the_reserved_word(text: str, word: str) -> None:
    with pytest.raises(ParseError, match=f"'{word}' is a reserved word"):
        parse(text)


def test_no_reserved_word_note_without_one() -> None:
    with pytest.raises(ParseError) as info:
        parse("p & (q")
    assert "reserved" not in str(info.value)


# --------------------------------------------------------------------------- layering


def _imports(path: pathlib.Path) -> list[tuple[str, bool]]:
    """Every module ``path`` imports, with whether the import sits inside a function."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    found: list[tuple[str, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.Import):
                found.extend((alias.name, nested) for alias in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module:
                found.extend((f"{child.module}.{alias.name}", nested) for alias in child.names)
            visit(child, nested)

    visit(tree, False)
    return found


_PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "mitld_lp"


def _module_file(name: str) -> pathlib.Path | None:
    """The package's file of the imported name ``name`` (a module, or a name in one)."""
    parts = name.split(".")[1:]
    while parts:
        for path in (_PACKAGE.joinpath(*parts).with_suffix(".py"),
                     _PACKAGE.joinpath(*parts, "__init__.py")):
            if path.is_file():
                return path
        parts.pop()
    return None


def _reached_at_import(start: pathlib.Path) -> set[pathlib.Path]:
    """The package's files that importing ``start`` runs (imports at module level)."""
    seen, todo = set(), [start]
    while todo:
        path = todo.pop()
        if path in seen:
            continue
        seen.add(path)
        todo += [f for m, inside in _imports(path) if not inside and m.startswith("mitld_lp.")
                 and (f := _module_file(m)) is not None]
    return seen


def test_the_laws_never_import_the_formula_layer() -> None:
    """``logic/`` imports ``distributions/``, never the reverse, and no import inside a
    function holds a cycle apart: scipy, and the laws' modules a model may not need (the
    fit, the bands, SciPy's laws), are imported lazily for speed, and each of those would
    import at the top without a cycle (it does not lead back to its importer)."""
    files = sorted((_PACKAGE / "distributions").glob("*.py"))
    assert {f.name for f in files} >= {"__init__.py", "law.py", "families.py", "literal.py"}
    for f in files:
        for module, in_function in _imports(f):
            assert not module.startswith("mitld_lp.logic"), f"{f.name} imports {module}"
            if in_function and not module.startswith("scipy"):
                target = _module_file(module)
                assert target is not None and target.parent == f.parent, (f.name, module)
                assert f not in _reached_at_import(target), f"{f.name} <-> {module}: a cycle"
    for f in ("syntax.py", "parser.py", "fragment.py"):
        lazy = [m for m, inside in _imports(_PACKAGE / "logic" / f) if inside]
        assert not [m for m in lazy if m.startswith("mitld_lp")], (f, lazy)


def test_no_module_of_the_laws_is_over_600_lines() -> None:
    for f in sorted((_PACKAGE / "distributions").glob("*.py")):
        assert len(f.read_text(encoding="utf-8").splitlines()) <= 600, f.name


def test_the_literal_node_is_the_laws_and_prints_as_before() -> None:
    """The formula layer's ``DistLiteral`` is the laws' own node; its text is the
    literal the parser reads back (an integral float keeps ``.0``)."""
    from mitld_lp import distributions, logic

    assert DistLiteral is distributions.DistLiteral is logic.syntax.DistLiteral
    lit = DistLiteral("scipy", ("nbinom", 3.0, 0.5, 1))
    assert str(lit) == "scipy(nbinom, 3.0, 0.5, 1)"
    assert parse_distribution(str(lit)) == lit


# --------------------------------------------------------------------------- built once

_INLINE_MODEL = """
name = "inline"
spec = "(D[poisson(2.5)] e & F(e & F[0,2] A)) | (D[pmf(0.25, 0.75)] f & F(f & B))"
[grid]
size = [3, 2]
start = [0, 0]
[regions]
A = [[2, 1]]
B = [[0, 1]]
"""


@pytest.fixture
def builds(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The text of every literal whose law is built from the registry, in order."""
    from mitld_lp.distributions import literal

    seen: list[str] = []
    real = literal.build

    def counting(family: str, args: tuple, where: str):  # type: ignore[no-untyped-def]
        seen.append(where)
        return real(family, args, where)

    monkeypatch.setattr(literal, "build", counting)
    return seen


def test_each_inline_law_is_built_once_per_load(builds: list[str]) -> None:
    """Parsing validates each literal by building its law; the fragment check and the
    binding of events reuse it (before: three builds per literal and load)."""
    model = M.loads_model(_INLINE_MODEL)
    assert sorted(builds) == ["pmf(0.25, 0.75)", "poisson(2.5)"]
    literals = {e: mu for e, mu in check(model.spec).events}
    for event in ("e", "f"):
        assert isinstance(literals[event], DistLiteral)
        assert model.distributions[event] is literals[event].law
    assert model.distributions["f"].pmf(2) == 0.75
    assert len(builds) == 2  # check() above built nothing either


def test_parse_then_check_then_bind_build_a_literal_once(builds: list[str]) -> None:
    f = parse("D[geometric(0.25)] a & F(a & b)")
    report = check(f)
    bound = M.bind_distributions(f)
    (_, mu), = report.events
    assert builds == ["geometric(0.25)"]
    assert bound["a"] is from_spec(mu) is mu.law
    assert bound["a"].hazard(7) == 0.25


def test_a_literal_equal_to_another_is_still_its_own_node() -> None:
    """The kept law is not part of the node's value: equality, hashing and pickling
    see the family and arguments only."""
    import pickle

    a, b = DistLiteral("geometric", (0.5,)), DistLiteral("geometric", (0.5,))
    assert a.law is not b.law and a.law is a.law
    assert a == b and hash(a) == hash(b)
    f = dist(a, Prop("e"))
    g = pickle.loads(pickle.dumps(f))
    assert g == f and g.mu.law.pmf(2) == 0.25
    bad = DistLiteral("geometric", (1.5,))  # making a literal checks nothing
    for _ in range(2):
        with pytest.raises(DistributionError, match=r"p must be in \(0, 1\]"):
            bad.law  # noqa: B018


# --------------------------------------------------------------------------- huge values

_BIG = str(10**400)
# One literal per family with its first number replaced by 10^400 (issue 16 item 9).
_HUGE_LITERALS = [
    f"geometric({_BIG})", f"pmf(0.5, {_BIG})", f"poisson({_BIG})", f"uniform(1, {_BIG})",
    f"exponential({_BIG})", f"weibull(1.5, {_BIG})", f"gamma({_BIG}, 1.5)",
    f"scipy(nbinom, {_BIG}, 0.5)", f"poisson(-{_BIG})",
]


def test_poisson_of_ten_to_the_400_is_one_line_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    """The reproduction of issue 16 item 9: an OverflowError traceback (exit 1) before."""
    assert main(["check", f"D[poisson({_BIG})] e & F e"]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.count("\n") == 1 and len(err) < 300
    assert err.startswith("mitld-lp: error: 1:3: D[poisson(1000")
    assert "lam is beyond the float range" in err and "integer of 401 digits" in err


@pytest.mark.parametrize("literal", _HUGE_LITERALS)
def test_huge_parameters_of_every_family_are_parse_errors_at_the_literal(
    literal: str, capsys: pytest.CaptureFixture[str]
) -> None:
    text = f"F[0,2] p & (q |\n  D[{literal}] b)"
    with pytest.raises(ParseError) as info:
        parse(text)
    assert (info.value.line, info.value.column) == (2, 5)
    assert "beyond the float range" in str(info.value) and "401 digits" in str(info.value)
    assert main(["check", text]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and "2:5: " in err


def _grid_model(spec: str, law: str = "") -> str:
    table = f"[distributions]\nmu = {{ {law} }}\n" if law else ""
    return (f'name = "big"\nspec = "{spec}"\n[grid]\nsize = [2, 2]\nstart = [0, 0]\n'
            f"[regions]\nA = [[1, 1]]\n{table}")


@pytest.mark.parametrize(
    ("law", "why"),
    [
        ("poisson = inf", "lam must be a finite number > 0, got inf"),
        ("geometric = nan", "p must be in (0, 1]"),
        ('scipy = ["nbinom", inf, 0.5]', "argument 1 must be a finite number, got inf"),
        ('scipy = ["nbinom", 0.5, nan]', "argument 2 must be a finite number, got nan"),
        ("weibull = [1.5, -inf]", "scale must be a finite number > 0"),
        ("uniform = [1, 1e300]", "b = an integer of 301 digits is beyond the last step"),
        ('scipy = ["hypergeom", 1e300, 5, 10]', "scipy.stats.hypergeom cannot evaluate"),
    ],
)
def test_model_files_refuse_values_no_float_holds_at_their_key_path(
    law: str, why: str, tmp_path, capsys: pytest.CaptureFixture[str]
) -> None:
    """TOML writes inf and nan as floats (and no integer beyond 64 bits): each is one
    line naming the file and the key path; ``nbinom(inf, 0.5)`` was solved to nan."""
    path = tmp_path / "big.toml"
    path.write_text(_grid_model("D[mu] e & F(e & F[0,1] A)", law), encoding="utf-8")
    with pytest.raises(M.ModelError) as info:
        M.load_model(path)
    family = law.split()[0]
    assert f"big.toml: distributions.mu.{family}: " in str(info.value)
    assert why in str(info.value)
    assert main(["solve", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and why in err


def test_a_model_files_inline_huge_literal_is_a_spec_error_with_its_position() -> None:
    with pytest.raises(M.ModelError, match=r"<string>: spec: 1:3: D\[poisson\(1000.* digits"):
        M.loads_model(_grid_model(f"D[poisson({_BIG})] e & F(e & F[0,1] A)"))
