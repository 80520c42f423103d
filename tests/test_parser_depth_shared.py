"""The parser's depth check walks the formula as a DAG: ``a W b`` shares ``b``, and a
chain of weak untils once took exponential time (24 of them: about a minute)."""

from __future__ import annotations

import pytest

from mitld_lp.logic import parser
from mitld_lp.logic.depth import formula_depth
from mitld_lp.logic.syntax import And, Dist, Next, Not, Or, Release, Until


def tree_depth(f) -> int:
    """The depth by plain recursion over every path (the definition, exponential)."""
    match f:
        case Not(a) | Next(a) | Dist(_, a):
            return 1 + tree_depth(a)
        case And(args) | Or(args):
            return 1 + max(tree_depth(a) for a in args)
        case Until(left, right, _) | Release(left, right, _):
            return 1 + max(tree_depth(left), tree_depth(right))
    return 1


@pytest.mark.parametrize("text", [
    "p", "!p", "p & (q | X r)", "p U[1,3] (q R r)", "G F[0,4] p",
    " W ".join(f"p{i}" for i in range(8)),
    "(p W q) & (q W (r W s))", "F (p W (q U[0,2] X r))",
])
def test_depth_is_the_tree_depth(text: str) -> None:
    f = parser.parse(text)
    assert formula_depth(f) == tree_depth(f)


def test_a_long_weak_until_chain_parses() -> None:
    # before the fix this loop would not end in the test's lifetime (2**n paths)
    text = " W ".join(f"p{i}" for i in range(60))
    try:
        f = parser.parse(text)
    except parser.ParseError as err:  # deeper than MAX_DEPTH: refused, not hung
        assert "deep" in str(err).lower() or "nest" in str(err).lower()
    else:
        assert formula_depth(f) >= 60
