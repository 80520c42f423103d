"""The plain parser (mitld_lp.logic.plain_parse) against lark's route: the same Source.

Lark's route (``mitld_lp.logic.parser`` with the plain parser switched off) is the
independent reference: for every formula here, hand-written and generated, the plain
parser's :class:`Source` is lark's, structure for structure (the formula, every law site
with its polarity, negation excerpt and position, every subformula's position); every
text lark rejects is left to lark (the plain parser answers None), so the error is
lark's, with its line and column.  A plain solve imports no lark.
"""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path

import pytest

from mitld_lp.logic import parser
from mitld_lp.logic.parser import ParseError, parse_source
from mitld_lp.logic.plain_parse import NESTING, plain_source
from mitld_lp.testing.fuzz import formula_text, random_formula

ROOT = Path(__file__).resolve().parent.parent

FORMULAS = [
    "p", "(p)", "((p))", "true", "false", "⊤", "⊥", "true & false | p", "!p", "~p", "¬p",
    "!!p", "!(p)", "X p", "X!p", "X(p)", "F p", "F(p)", "◇ p", "F[0,3] p", "F[2,2] p",
    "F<=3 p", "F ≤ 3 p", "G p", "□ p", "G[1,4] p", "G<=0 p", "G G p", "F G F p",
    "p & q", "p && q", "p ∧ q", "p | q", "p || q", "p ∨ q", "p -> q", "p → q",
    "a -> b -> !c", "(a -> b) -> c", "p U q", "p 𝒰 q", "p U[1,2] q", "p U<=5 q",
    "p U q U r", "(p U q) U r", "p R q", "p R[0,2] q", "p R<=2 q", "p W q", "p W q W r",
    "p U q & r", "p & q U r", "p | q & r", "(p | q) & r", "!p U q", "F p U G q",
    "p & q & r & s", "p | (q | r) | s", "p & p", "p | !p", "F true", "G false",
    "p U false", "p U true", "p U[1,2] true", "p R true", "p R false", "p R[1,3] false",
    "X true", "X false", "F1 & Fx", "Xp | Up", "true_a & false0 & _x & D1", "a_b_9",
    "D[mu] e", "D[mu] (e)", "D[mu] e & F(e & A)", "!(a & D[mu] e)", "!(D[mu] e) -> D[nu] f",
    "(a -> (D[mu] e & b)) & !(!(D[nu] f))", "D[mu] e & false", "(D[mu] e & false) | F(e & A)",
    "D[geometric(0.3)] e", "D[geometric(1)] e", "D[geometric(.5)] e", "D[geometric(5e-1)] e",
    "D[pmf(0.1, 0.9)] e", "D[pmf(0.25,0.25,0.5)] e", "D[uniform(1,3)] e",
    "D[poisson(2.5)] e", "D[poisson(3)] e", "D[scipy(nbinom, 3, 0.5)] e",
    "(D[mu1] e1 & F(e1 & F[0,3] A)) | (D[mu2] e2 & F[1,4] (e2 & B))",
    "D[mu] D[nu] e", "G(D[mu] e -> F[0,2] e)", "!(p -> D[mu] e)",
    "  p\n  &\n (q |\n r)", "\tp\r\n&\fq", "p&q|r->s", "F[0,3]p", "(((a)))&((b))",
    "!((D[mu] e) & (p))", "((D[mu] e)) -> ((p))", "x1 U[0,10] (y2 R z3)",
    "G<=4 (a -> X (b W c))", "F[0,1000000000000] p", "F[007,010] p",
]

REJECTED = [
    "", " ", "p &", "& p", "p q", "(p", "p)", "()", "F", "F[3,1] p", "F[0,3 p", "F[0,] p",
    "F[,3] p", "F[0.5,3] p", "F[0,3e1] p", "F<= p", "F <= -1 p", "p W[0,3] q", "p W<=3 q",
    "X[0,1] p", "D[mu] ", "D mu e", "D[] e", "D[mu e", "D[geometric(1.5)] e",
    "D[geometric()] e", "D[geometric(0.1, 0.2)] e", "D[nosuch(1)] e", "D[uniform(1.5,3)] e",
    "D[uniform(3,1)] e", "D[pmf(0.6, 0.6)] e", "D[scipy(1, 2)] e", "D[geometric(a)] e",
    "D[geometric(1e999)] e", "F (D & E)", "p & F", "U p", "p U", "true false", "p @ q",
    "p\u00a0& q", "p & q\v", "é", "p & \u2227\u2227 q", "p U[1,2]", "((p)", "p -> ",
    "F[0," + "9" * 5000 + "] p", "-p", "p - q", "1 & p", "p & 2.5", "p, q", "[p]",
    "p ]", "< = 3", "F < 3 p", "G<=3", "D[mu](e", "D[mu]] e",
]


def _lark(text: str, monkeypatch: pytest.MonkeyPatch):
    """Lark's route: ``parse_source`` with the plain parser answering None."""
    with monkeypatch.context() as m:
        m.setattr(parser, "plain_source", lambda t: None)
        try:
            return parse_source(text)
        except ParseError as err:
            return err


def _same(plain, lark) -> None:
    assert plain.text == lark.text
    assert plain.formula == lark.formula
    assert plain.laws == lark.laws  # each site: node, polarity, negation excerpt, place
    assert dict(plain.positions) == dict(lark.positions)


@pytest.mark.parametrize("text", FORMULAS)
def test_plain_formula_is_larks(text, monkeypatch):
    lark = _lark(text, monkeypatch)
    assert not isinstance(lark, ParseError), lark
    plain = plain_source(text)
    assert plain is not None, "left to lark"
    _same(plain, lark)
    _same(parse_source(text), lark)


@pytest.mark.parametrize("text", REJECTED)
def test_rejected_text_goes_to_lark_with_its_error(text, monkeypatch):
    lark = _lark(text, monkeypatch)
    assert isinstance(lark, ParseError)  # a text lark rejects...
    assert plain_source(text) is None  # ...the plain parser leaves to lark
    with pytest.raises(ParseError) as got:
        parse_source(text)
    err = got.value
    assert (str(err), err.line, err.column, err.text, err.expected) == (
        str(lark), lark.line, lark.column, lark.text, lark.expected)


def test_positions_by_hand():
    # columns counted by hand: "!" at 1, "(" at 2, "a" at 3, "D" at 7, "e" at 14
    s = plain_source("!(a & D[mu] e)")
    (site,) = s.laws
    assert (site.line, site.column, site.positive) == (1, 7, False)
    assert site.negation == "!(a & D[mu] e)"
    f = s.formula
    assert s.position(f) == (1, 1)
    s2 = plain_source("p\n  & (q)")
    q = s2.formula.args[1]
    assert s2.position(q) == (2, 6)  # the name itself, its parentheses aside


# tokens a generated text is made of: every operator spelling, names, numbers, brackets
_TOKENS = ["p", "q", "e", "A", "F1", "mu", "true", "false", "⊤", "⊥", "!", "~", "¬", "&",
           "&&", "∧", "|", "||", "∨", "->", "→", "X", "F", "◇", "G", "□", "U", "𝒰", "R",
           "W", "D", "(", ")", "[", "]", ",", "<=", "≤", "0", "1", "3", "2.5", "-",
           "geometric", "pmf", "0.5"]


def _agree(text: str, monkeypatch: pytest.MonkeyPatch) -> bool:
    """Lark's answer and the plain parser's agree on ``text``; whether lark accepts it."""
    lark = _lark(text, monkeypatch)
    plain = plain_source(text)
    if isinstance(lark, ParseError):
        assert plain is None, text  # left to lark
        return False
    assert plain is not None, text
    _same(plain, lark)
    return True


_SPACES = (" ", "  ", "\n", "\t", " \r\n ", "\f")


@pytest.mark.parametrize("seed", range(4))
def test_generated_formulas_are_larks(seed, monkeypatch):
    # formulas shaped by the grammar, often with invalid bounds or laws (the fuzzer's),
    # with other spacing, some until a weak until, and with fewer parentheses
    rng = random.Random(seed)
    accepted = 0
    for i in range(200):
        text = random_formula(rng, 5) if i % 2 else formula_text(rng)
        text = text.replace(" ", rng.choice(_SPACES))
        if rng.random() < 0.3:
            text = text.replace(" U", " W", 1)
        if rng.random() < 0.3:
            text = text.replace("(", "", 1).replace(")", "", 1)
        accepted += _agree(text, monkeypatch)
    assert accepted > 20


@pytest.mark.parametrize("seed", range(4))
def test_random_token_strings_agree_with_lark(seed, monkeypatch):
    rng = random.Random(100 + seed)
    accepted = 0
    for _ in range(300):
        text = rng.choice(["", " "]).join(rng.choice(_TOKENS)
                                           for _ in range(rng.randint(1, 8)))
        accepted += _agree(text, monkeypatch)
    assert accepted > 0


def test_deep_nesting_goes_to_lark(monkeypatch):
    deep = "(" * (NESTING + 5) + "p" + ")" * (NESTING + 5)
    assert plain_source(deep) is None
    assert parse_source(deep).formula == _lark(deep, monkeypatch).formula
    too_deep = "X " * 300 + "p"  # beyond MAX_DEPTH: lark's error, the same either way
    assert isinstance(_lark(too_deep, monkeypatch), ParseError)
    with pytest.raises(ParseError, match="nested too deeply"):
        parse_source(too_deep)
    # a shallow text whose formula is deeper than MAX_DEPTH (W doubles its right
    # operand's depth): refused, with lark's error (a lower limit keeps it small)
    monkeypatch.setattr(parser, "MAX_DEPTH", 10)
    chain = " W ".join("abcdefgh")
    assert plain_source(chain) is not None  # the text is plain...
    lark = _lark(chain, monkeypatch)
    assert isinstance(lark, ParseError)  # ...its formula too deep
    with pytest.raises(ParseError) as got:
        parse_source(chain)
    assert str(got.value) == str(lark)


def test_a_plain_parse_imports_no_lark():
    code = ("import sys\nfrom mitld_lp.logic import parse_source, check\n"
            "s = parse_source('(D[mu1] e1 & F(e1 & F[0,3] A)) | G<=4 !B')\n"
            "check(s)\nprint(sorted(m for m in sys.modules if m.partition('.')[0] == 'lark'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"
