"""What a formula's text says beyond the formula it simplifies to.

The parser builds formulas with the simplifying constructors of
:mod:`mitld_lp.logic.syntax`, so ``(D[mu] e & false) | F(e & A)`` *is* the formula
``F(e & A)``: the operand that carried the distribution of ``e`` is gone.  But the text
still declared ``e`` an event with law ``mu``, and a task's meaning must not depend on
which operands a constant happens to absorb.  A :class:`Source` keeps, next to the
simplified formula,

* every ``D[mu] a`` the text writes (a :class:`LawSite`), with its polarity counted on
  the text (under ``!`` or on the left of ``->``), whether or not the formula kept it;
* the line and column where each subformula is first written, so that a message about a
  subformula can point at it.

:func:`mitld_lp.logic.parser.parse_source` makes one; :func:`mitld_lp.logic.fragment.check`
reads the events from its sites rather than from the simplified formula.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from mitld_lp.logic.syntax import Dist, Formula
from mitld_lp.util.text import printable

TYPE_CHECKING = False
if TYPE_CHECKING:
    from lark import Tree

__all__ = ["LawSite", "Source", "source_of"]

#: Longest excerpt of the text quoted in a message.
EXCERPT = 60

# Rules of grammar.lark whose result is a formula.
_FORMULA_RULES = frozenset(
    {"start", "true", "false", "prop", "neg", "nxt", "eventually", "always", "dist",
     "until", "release", "weak", "conj", "disj", "implies"}
)


@dataclass(frozen=True, slots=True)
class LawSite:
    """One ``D[mu] a`` as the text writes it.

    Attributes:
        dist: the node the parser built (its operand simplified, ``D[mu] (a & true)`` is
            ``D[mu] a``).
        positive: under an even number of negations in the text (``!`` and the left side
            of ``->`` each count one).
        negation: the text of the innermost negating construct around it (shortened), or
            ``None`` when it stands under none.
        line, column: where ``D`` is written (1-based).
    """

    dist: Dist
    positive: bool
    negation: str | None
    line: int
    column: int


@dataclass(frozen=True, slots=True)
class Source:
    """A parsed formula with what its text says beyond it (see the module docstring).

    Attributes:
        text: the text as given.
        formula: the formula it simplifies to (what :func:`~mitld_lp.logic.parser.parse`
            returns).
        laws: every ``D[mu] a`` of the text, in the order written.
        positions: for each subformula the parser built, the ``(line, column)`` where it
            is first written.
    """

    text: str
    formula: Formula
    laws: tuple[LawSite, ...]
    positions: Mapping[Formula, tuple[int, int]]

    def position(self, f: Formula) -> tuple[int, int] | None:
        """Where ``f`` is first written, or ``None`` when the text never builds it as
        such (a node the simplification made)."""
        return self.positions.get(f)


def excerpt(text: str) -> str:
    """``text`` on one line (whitespace runs collapsed, control characters escaped), cut
    to :data:`EXCERPT` characters."""
    one = printable(" ".join(text.split()))
    return one if len(one) <= EXCERPT else one[: EXCERPT - 3] + "..."


def source_of(text: str, tree: Tree, built: Mapping[int, object]) -> Source:
    """The :class:`Source` of ``text`` from its parse ``tree`` (built with
    ``propagate_positions``) and ``built``, the value made of each tree node (by
    ``id``).  Walks the tree from the root, left to right, counting negations.  A tree
    is read through ``data``, ``children`` and ``meta`` alone (lark's, or
    :mod:`mitld_lp.logic.plain_parse`'s nodes, which import no lark)."""
    positions: dict[Formula, tuple[int, int]] = {}
    laws: list[LawSite] = []
    stack: list[tuple[Tree, bool, Tree | None]] = [(tree, True, None)]
    while stack:
        node, positive, negation = stack.pop()
        value = built[id(node)]
        where = (node.meta.line, node.meta.column)
        assert isinstance(value, Formula)
        positions.setdefault(value, where)
        if node.data == "dist":
            assert isinstance(value, Dist)
            shown = None
            if negation is not None:
                shown = excerpt(text[negation.meta.start_pos : negation.meta.end_pos])
            laws.append(LawSite(value, positive, shown, *where))
        children = [c for c in node.children
                    if getattr(c, "data", None) in _FORMULA_RULES]  # no token has data
        for i in reversed(range(len(children))):
            flips = node.data == "neg" or (node.data == "implies" and i == 0)
            stack.append((children[i], positive != flips, node if flips else negation))
    return Source(text, built[id(tree)], tuple(laws), MappingProxyType(positions))  # type: ignore[arg-type]
