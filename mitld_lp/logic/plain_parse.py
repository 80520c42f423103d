"""The formulas a task writes, parsed without lark: the same :class:`Source`, sooner.

:func:`mitld_lp.logic.parser.parse_source` asks :func:`plain_source` first.  It reads the
grammar of ``grammar.lark`` by recursive descent, one method a rule, and builds each
node with the very smart constructors, in the very order, of the lark route's
transformer; the positions of :class:`~mitld_lp.logic.source.Source` come from a tree of
its own whose nodes carry what lark's ``propagate_positions`` gives its trees (a node
starts where its first child's *container* starts -- the outermost parentheses around
an operand -- and ends where its last child's container ends), walked by the same
:func:`~mitld_lp.logic.source.source_of`.

It answers None, and the caller goes to lark, at the first thing it does not accept:
any syntax error, an empty interval, an integer too long, a distribution literal of the
wrong shape or values, nesting deeper than :data:`NESTING`, a character outside the
grammar.  So every message about a malformed formula is lark's, with its line and
column, and a solve whose task is well formed imports neither lark nor its tables
(0.02-0.03 s of CPU at every start).  ``tests/test_plain_parse.py`` compares the two
routes' results on many formulas and their errors on many rejected texts.
"""

from __future__ import annotations

import math
import re

from mitld_lp.distributions import FAMILIES, DistLiteral, DistributionError
from mitld_lp.logic import syntax as sx
from mitld_lp.logic.source import Source, source_of
from mitld_lp.logic.syntax import RESERVED, DistRef, Formula, Interval
from mitld_lp.util.decimals import Written

__all__ = ["NESTING", "plain_source"]

#: Deeper nesting than this (operands within operands) goes to lark, which checks it
#: against :data:`mitld_lp.logic.parser.MAX_DEPTH` without the Python stack.
NESTING = 60

# The grammar's terminals in the order lark's basic lexer tries them: FLOAT first (its
# priority), then the unbounded patterns, then the strings, longest first.
_TOKENS = re.compile(
    r"(?P<FLOAT>(?:[0-9]+\.[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[0-9]+[eE][+-]?[0-9]+)"
    r"|(?P<NAME>[A-Za-z_][A-Za-z0-9_]*)|(?P<INT>[0-9]+)|(?P<WS>[ \t\r\n\f]+)"
    r"|(?P<OP>&&|\|\||->|<=|[!~¬&∧|∨→◇□𝒰⊤⊥()\[\],≤-])"
)

# Each operator's and keyword's spelling -> the kind the parser reads.
_KIND = {
    "!": "NOT", "~": "NOT", "¬": "NOT", "&&": "AND", "&": "AND", "∧": "AND",
    "||": "OR", "|": "OR", "∨": "OR", "->": "IMPLIES", "→": "IMPLIES",
    "<=": "LE", "≤": "LE", "◇": "F", "□": "G", "𝒰": "U", "⊤": "true", "⊥": "false",
    "(": "(", ")": ")", "[": "[", "]": "]", ",": ",", "-": "-",
}
for _word in RESERVED:
    _KIND[_word] = _word


class _Refused(Exception):
    """Not for this parser: lark parses the text (and phrases the error)."""


class _Meta:
    """What :func:`source_of` reads of a node's ``meta``: where it is written."""

    __slots__ = ("line", "column", "start_pos", "end_pos")


class _Node:
    """A formula node as lark's tree would hold it (its formula children only)."""

    __slots__ = ("data", "children", "meta", "outer", "outer_end")

    def __init__(self, data: str, children: list[_Node], start: int, end: int) -> None:
        self.data = data
        self.children = children
        self.meta = _Meta()
        self.meta.start_pos, self.meta.end_pos = start, end
        self.outer, self.outer_end = start, end  # the container: parentheses around it


class _Parser:
    def __init__(self, text: str) -> None:
        self.text = text
        self.kinds: list[str] = []
        self.values: list[str] = []
        self.starts: list[int] = []
        pos, n = 0, len(text)
        while pos < n:
            m = _TOKENS.match(text, pos)
            if m is None:
                raise _Refused
            kind = m.lastgroup
            value = m.group()
            if kind == "OP" or (kind == "NAME" and value in RESERVED):
                kind = _KIND[value]
            if kind != "WS":
                self.kinds.append(kind)
                self.values.append(value)
                self.starts.append(pos)
            pos = m.end()
        self.kinds.append("$END")
        self.starts.append(n)
        self.i = 0
        self.depth = 0
        self.built: dict[int, object] = {}

    # tokens
    def peek(self) -> str:
        return self.kinds[self.i]

    def take(self, kind: str) -> int:
        """Consume a token of ``kind``; its index."""
        if self.kinds[self.i] != kind:
            raise _Refused
        self.i += 1
        return self.i - 1

    def end_of(self, tok: int) -> int:
        return self.starts[tok] + len(self.values[tok])

    def node(self, data: str, children: list[_Node], value: Formula, start: int,
             end: int) -> _Node:
        n = _Node(data, children, start, end)
        self.built[id(n)] = value
        return n

    def value(self, n: _Node) -> Formula:
        return self.built[id(n)]  # type: ignore[return-value]

    def deeper(self) -> None:
        self.depth += 1
        if self.depth > NESTING:
            raise _Refused

    # rules
    def start(self) -> _Node:
        f = self.implication()
        self.take("$END")
        return self.node("start", [f], self.value(f), f.outer, f.outer_end)

    def implication(self) -> _Node:
        left = self.disjunction()
        if self.peek() != "IMPLIES":
            return left
        self.i += 1
        self.deeper()
        right = self.implication()
        self.depth -= 1
        return self.node("implies", [left, right], sx.implies(self.value(left), self.value(right)),
                         left.outer, right.outer_end)

    def _nary(self, op: str, data: str, operand, build) -> _Node:
        first = operand()
        if self.peek() != op:
            return first
        parts = [first]
        while self.peek() == op:
            self.i += 1
            parts.append(operand())
        return self.node(data, parts, build(*(self.value(p) for p in parts)), first.outer,
                         parts[-1].outer_end)

    def disjunction(self) -> _Node:
        return self._nary("OR", "disj", self.conjunction, sx.disj)

    def conjunction(self) -> _Node:
        return self._nary("AND", "conj", self.binary, sx.conj)

    def binary(self) -> _Node:
        left = self.unary()
        kind = self.peek()
        if kind not in ("U", "R", "W"):
            return left
        self.i += 1
        bounds = self.bounds() if kind != "W" else None
        self.deeper()
        right = self.binary()
        self.depth -= 1
        lv, rv = self.value(left), self.value(right)
        if kind == "U":
            data, value = "until", sx.until(lv, rv, bounds)
        elif kind == "R":
            data, value = "release", sx.release(lv, rv, bounds)
        else:
            data, value = "weak", sx.weak(lv, rv)
        return self.node(data, [left, right], value, left.outer, right.outer_end)

    def unary(self) -> _Node:
        kind = self.peek()
        if kind not in ("NOT", "X", "F", "G", "D"):
            return self.atom()
        first = self.starts[self.i]
        self.i += 1
        mu = None
        bounds = self.bounds() if kind in ("F", "G") else None
        if kind == "D":
            self.take("[")
            mu = self.dist_spec()
            self.take("]")
        self.deeper()
        arg = self.unary()
        self.depth -= 1
        a = self.value(arg)
        if kind == "NOT":
            data, value = "neg", sx.neg(a)
        elif kind == "X":
            data, value = "nxt", sx.nxt(a)
        elif kind == "F":
            data, value = "eventually", sx.eventually(a, bounds)
        elif kind == "G":
            data, value = "always", sx.always(a, bounds)
        else:
            if isinstance(mu, DistLiteral):
                try:
                    mu.law  # noqa: B018 - built here, kept by the literal (the lark route's)
                except DistributionError:
                    raise _Refused from None
            data, value = "dist", sx.dist(mu, a)  # type: ignore[arg-type]
        return self.node(data, [arg], value, first, arg.outer_end)

    def atom(self) -> _Node:
        kind = self.peek()
        start = self.starts[self.i]
        if kind in ("true", "false", "NAME"):
            tok = self.i
            self.i += 1
            value = sx.TRUE if kind == "true" else sx.FALSE if kind == "false" else sx.Prop(
                self.values[tok])
            data = kind if kind != "NAME" else "prop"
            return self.node(data, [], value, start, self.end_of(tok))
        self.take("(")
        self.deeper()
        inner = self.implication()
        self.depth -= 1
        close = self.take(")")
        inner.outer, inner.outer_end = start, self.end_of(close)
        return inner

    def bounds(self) -> Interval | None:
        kind = self.peek()
        if kind == "LE":
            self.i += 1
            return Interval(0, self.integer())
        if kind != "[":
            return None
        self.i += 1
        lo = self.integer()
        self.take(",")
        hi = self.integer()
        self.take("]")
        if lo > hi:
            raise _Refused  # lark says where, and why
        return Interval(lo, hi)

    def integer(self) -> int:
        tok = self.take("INT")
        try:
            return int(self.values[tok])
        except ValueError:  # too many digits for int()
            raise _Refused from None

    def dist_spec(self) -> DistRef | DistLiteral:
        name = self.values[self.take("NAME")]
        if self.peek() != "(":
            return DistRef(name)
        self.i += 1
        args: list[object] = []
        if self.peek() != ")":
            args.append(self.dist_arg())
            while self.peek() == ",":
                self.i += 1
                args.append(self.dist_arg())
        self.take(")")
        fam = FAMILIES.get(name)
        if fam is None or fam.arity_error(len(args)) is not None:
            raise _Refused
        for i, value in enumerate(args):
            if i < int(fam.named):
                if not isinstance(value, str):
                    raise _Refused
            elif isinstance(value, str) or (fam.integers and not isinstance(value, int)):
                raise _Refused
        return DistLiteral(name, tuple(args))  # type: ignore[arg-type]

    def dist_arg(self) -> object:
        kind = self.peek()
        if kind == "NAME":
            self.i += 1
            return self.values[self.i - 1]
        minus = kind == "-"
        if minus:
            self.i += 1
        if self.peek() == "INT":
            value = self.integer()
            return -value if minus else value
        written = Written(self.values[self.take("FLOAT")])
        if not math.isfinite(written):
            raise _Refused
        return Written(f"-{written.text}") if minus else written


def _lines(text: str, nodes: list[_Node]) -> None:
    """Each node's line and column (1-based, in characters) from its start."""
    for n in nodes:
        pos = n.meta.start_pos
        n.meta.line = text.count("\n", 0, pos) + 1
        n.meta.column = pos - text.rfind("\n", 0, pos)


def plain_source(text: str) -> Source | None:
    """The :class:`Source` lark's route makes of ``text`` (a str), or None where this
    parser leaves ``text`` to lark (see the module docstring)."""
    try:
        p = _Parser(text)
        root = p.start()
    except (_Refused, RecursionError):
        return None
    nodes: list[_Node] = []
    stack = [root]
    while stack:
        n = stack.pop()
        nodes.append(n)
        stack.extend(n.children)
    _lines(text, nodes)
    return source_of(text, root, p.built)  # type: ignore[arg-type]
