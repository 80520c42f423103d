"""Parse the ASCII (or Unicode) MITLD syntax into the AST of :mod:`mitld_lp.logic.syntax`.

Syntax (see ``grammar.lark`` beside this file)::

    true  false  a  !p  p & q  p | q  p -> q  p U q  p U[l,u] q  p R q  p R[l,u] q
    F p  F[l,u] p  G p  G[l,u] p  X p  D[mu] a        F<=k p == F[0,k] p (also G<=k, U<=k, R<=k)
    p W q  (weak until, no interval: p U q | G p)

Precedence, loosest first: ``->`` (right-associative), ``|``, ``&``, ``U``/``R``/``W``
(right-associative: ``p U q U r == p U (q U r)``; :func:`str` parenthesises nested binary
temporal operators anyway), unary (``! X F G D``).  Synonyms: ``¬ ~`` for ``!``, ``∧ &&``
for ``&``, ``∨ ||`` for ``|``, ``→`` for ``->``, ``◇`` for ``F``, ``□`` for ``G``, ``𝒰`` for
``U``, ``⊤``/``⊥`` for ``true``/``false``, ``≤`` for ``<=``.

Identifiers are ASCII letters, digits and ``_``, not starting with a digit.  The words
``true false X F G U R W D`` are reserved: an identifier is read whole and is an operator
only when it is exactly one of them.  So ``F1``, ``Fx``, ``Xp`` and ``Up`` are
propositions, while ``F p``, ``F(p)``, ``F[0,3] p``, ``F<=3 p`` and ``X!p`` apply the
operators (a keyword needs a space before an identifier operand).

Interval bounds are non-negative integers with ``l <= u``.  A distribution ``mu`` is a
name (:class:`DistRef`, bound later from a model file) or a literal ``family(args)``
(:class:`DistLiteral`) of one of the families of
:data:`mitld_lp.distributions.FAMILIES`; integers parse to ``int``, decimals and exponent
forms to ``float``.  A literal's law is built here, once, to validate its values, so
``D[geometric(1.5)] a`` is a :class:`ParseError` at the literal; the literal keeps the
law (:attr:`DistLiteral.law`) for the stages after parsing.

Every malformed input raises :class:`ParseError` (a ``ValueError``) with the line and
column of the offending token, never another exception.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from functools import cache

from mitld_lp.distributions import (
    FAMILIES,
    DistArg,
    DistLiteral,
    DistributionError,
    Family,
)
from mitld_lp.logic import tables
from mitld_lp.logic.depth import formula_depth
from mitld_lp.logic.plain_parse import plain_source
from mitld_lp.logic.source import Source, source_of
from mitld_lp.logic.syntax import (
    FALSE,
    RESERVED,
    TRUE,
    DistRef,
    DistSpec,
    Formula,
    Interval,
    Prop,
    always,
    conj,
    disj,
    dist,
    eventually,
    implies,
    neg,
    nxt,
    release,
    until,
    weak,
)
from mitld_lp.util.decimals import Written
from mitld_lp.util.text import excerpt

# lark and its tables are imported where a text goes to lark: a formula the plain
# parser leaves to it (a malformed one among them), a distribution written alone
TYPE_CHECKING = False
if TYPE_CHECKING:
    from lark import Token, Tree
    from lark.exceptions import UnexpectedInput, UnexpectedToken

__all__ = ["ParseError", "parse", "parse_source", "parse_distribution", "MAX_DEPTH"]

#: Formulas nested deeper than this are refused: every later stage walks formulas
#: recursively, and a parse error is better than a ``RecursionError`` far away.
MAX_DEPTH = 200


class ParseError(ValueError):
    """A malformed formula or distribution literal.

    ``line`` and ``column`` are 1-based; ``text`` is the offending token or snippet
    (``""`` at the end of the input); ``expected`` names what would have been accepted
    there (empty when the input is well formed but meaningless, e.g. ``[3,1]``).
    ``str(err)`` is one line, ``"1:7: unexpected ')'; expected a formula"``;
    :meth:`context` adds the source line and a caret under the column.
    """

    def __init__(
        self,
        reason: str,
        *,
        line: int,
        column: int,
        text: str,
        expected: Iterable[str] = (),
        source: str = "",
    ) -> None:
        self.reason = reason
        self.line = line
        self.column = column
        self.text = text
        self.expected: tuple[str, ...] = tuple(expected)
        self.source = source
        super().__init__(f"{line}:{column}: {reason}")

    def __reduce__(self):  # keyword-only fields: rebuild from all of them
        return (
            _rebuild_parse_error,
            (self.reason, self.line, self.column, self.text, self.expected, self.source),
        )

    def context(self) -> str:
        """The offending source line with a caret under the error column."""
        lines = self.source.splitlines() or [""]
        src = lines[self.line - 1] if 1 <= self.line <= len(lines) else ""
        return f"{src}\n{' ' * max(self.column - 1, 0)}^"


def _rebuild_parse_error(
    reason: str, line: int, column: int, text: str, expected: tuple[str, ...], source: str
) -> ParseError:
    return ParseError(reason, line=line, column=column, text=text, expected=expected, source=source)


# --------------------------------------------------------------------------- distributions


def _shape_text(fam: Family) -> str:
    kind = "integer" if fam.integers else "number"
    if fam.named:
        return f"{fam.name}(name, {kind}s...)"
    if fam.max_numbers is None:
        return f"{fam.name}({kind}, ...) with at least {fam.min_numbers} {kind}"
    lo = fam.min_numbers
    return f"{fam.name} takes {lo} {kind}{'s' if lo != 1 else ''}"


# --------------------------------------------------------------------------- transformer


def _pos(tok: Token) -> tuple[int, int]:
    return (tok.line or 1, tok.column or 1)


class _Build:
    """Each rule of the grammar maps onto one smart constructor of ``syntax``; a method
    receives the rule's children already built (see :func:`_transform`)."""

    def __init__(self, source: str) -> None:
        self.source = source
        # inline laws by identity, with the token of their family name (for positions)
        self._literals: dict[int, tuple[DistLiteral, Token]] = {}

    def _error(self, reason: str, tok: Token) -> ParseError:
        line, column = _pos(tok)
        return ParseError(reason, line=line, column=column, text=str(tok), source=self.source)

    # formulas
    def start(self, c: list) -> Formula:
        return c[0]

    def true(self, _c: list) -> Formula:
        return TRUE

    def false(self, _c: list) -> Formula:
        return FALSE

    def prop(self, c: list) -> Formula:
        return Prop(str(c[0]))

    def neg(self, c: list) -> Formula:
        return neg(c[0])

    def nxt(self, c: list) -> Formula:
        return nxt(c[0])

    def eventually(self, c: list) -> Formula:
        return eventually(c[1], c[0])

    def always(self, c: list) -> Formula:
        return always(c[1], c[0])

    def dist(self, c: list) -> Formula:
        self._validate(c[1], f"D[{c[1]}] {c[2]}")
        return dist(c[1], c[2])

    def until(self, c: list) -> Formula:
        return until(c[0], c[2], c[1])

    def release(self, c: list) -> Formula:
        return release(c[0], c[2], c[1])

    def weak(self, c: list) -> Formula:
        return weak(c[0], c[1])

    def conj(self, c: list) -> Formula:
        return conj(*c)

    def disj(self, c: list) -> Formula:
        return disj(*c)

    def implies(self, c: list) -> Formula:
        return implies(c[0], c[1])

    def _int(self, tok: Token) -> int:
        try:
            return int(tok)
        except ValueError:  # more digits than int() converts (sys.get_int_max_str_digits)
            raise self._error(f"integer too long ({len(tok)} digits)", tok) from None

    def _float(self, tok: Token) -> Written:
        value = Written(str(tok))  # the decimal as written, for an exact answer
        if not math.isfinite(value):
            raise self._error(f"number out of range: {tok}", tok)
        return value

    # intervals
    def interval(self, c: list) -> Interval:
        bracket, lo, hi = c
        lo_i, hi_i = self._int(lo), self._int(hi)
        if lo_i > hi_i:
            raise self._error(
                f"empty interval [{lo_i},{hi_i}]: lower bound {lo_i} exceeds upper bound {hi_i}",
                bracket,
            )
        return Interval(lo_i, hi_i)

    def upto(self, c: list) -> Interval:
        return Interval(0, self._int(c[1]))

    # distributions
    def dist_start(self, c: list) -> DistSpec:
        self._validate(c[0], str(c[0]))
        return c[0]

    def dist_ref(self, c: list) -> DistSpec:
        return DistRef(str(c[0]))

    def dist_literal(self, c: list) -> DistSpec:
        family_tok: Token = c[0]
        args: list[tuple[DistArg, Token]] = c[1] if c[1] is not None else []
        family = str(family_tok)
        fam = FAMILIES.get(family)
        if fam is None:
            raise self._error(
                f"unknown distribution family {family!r}; expected one of "
                f"{', '.join(sorted(FAMILIES))}",
                family_tok,
            )
        if fam.arity_error(len(args)) is not None:
            raise self._error(
                f"{family}(...) has {len(args)} argument{'s' if len(args) != 1 else ''}; "
                f"{_shape_text(fam)}",
                family_tok,
            )
        for i, (value, tok) in enumerate(args):
            if i < int(fam.named):
                if not isinstance(value, str):
                    raise self._error(f"{family}: argument {i + 1} must be a name", tok)
            elif isinstance(value, str):
                raise self._error(f"{family}: argument {i + 1} must be a number", tok)
            elif fam.integers and not isinstance(value, int):
                raise self._error(f"{family}: argument {i + 1} must be an integer", tok)
        literal = DistLiteral(family, tuple(v for v, _ in args))
        self._literals[id(literal)] = (literal, family_tok)
        return literal

    def _validate(self, mu: DistSpec, what: str) -> None:
        """Build an inline law to check its values (``geometric(1.5)``, ``pmf(0.6, 0.6)``),
        reporting at the literal's family name; a name is bound later.  The literal keeps
        the law it built (:attr:`DistLiteral.law`), so the later stages reuse it.  The
        message quotes a long literal as an excerpt."""
        if not isinstance(mu, DistLiteral):
            return
        _, tok = self._literals[id(mu)]
        try:
            mu.law  # noqa: B018 - built here, kept by the literal
        except DistributionError as err:
            raise self._error(f"{excerpt(what)}: {err.reason}", tok) from None

    def dist_args(self, c: list) -> list[tuple[DistArg, Token]]:
        return c

    def arg_name(self, c: list) -> tuple[DistArg, Token]:
        return (str(c[0]), c[0])

    def arg_int(self, c: list) -> tuple[DistArg, Token]:
        value = self._int(c[-1])
        return (-value if len(c) == 2 else value, c[0])

    def arg_float(self, c: list) -> tuple[DistArg, Token]:
        value = self._float(c[-1])
        return (Written(f"-{value.text}") if len(c) == 2 else value, c[0])


# --------------------------------------------------------------------------- errors

_FORMULA_START = frozenset(
    {
        "NAME",
        "_TRUE",
        "_TOP",
        "_FALSE",
        "_BOTTOM",
        "_NOT",
        "_NEXT",
        "_EVENTUALLY",
        "_DIAMOND",
        "_ALWAYS",
        "_BOX",
        "_DIST",
        "_LPAR",
    }
)
_OPERATORS = frozenset({"_AND", "_OR", "_IMPLIES", "_UNTIL", "_SCRIPT_U", "_RELEASE", "_WEAK"})
_DESCRIBE = {
    "_RPAR": "')'",
    "_LPAR": "'('",
    "_RSQB": "']'",
    "LSQB": "'['",
    "_COMMA": "','",
    "LE": "'<='",
    "INT": "an integer",
    "FLOAT": "a number",
    "NAME": "a name",
    "$END": "end of input",
}


def _describe_expected(names: Iterable[str]) -> tuple[str, ...]:
    names = set(names)
    out: list[str] = []
    if _FORMULA_START <= names:
        out.append("a formula")
        names -= _FORMULA_START
    if names & _OPERATORS:
        out.append("an operator")
        names -= _OPERATORS
    if {"INT", "FLOAT"} <= names:
        out.append("a number")
        names -= {"INT", "FLOAT", "MINUS"}
    names.discard("MINUS")
    order = ["NAME", "INT", "FLOAT", "LSQB", "LE", "_LPAR", "_COMMA", "_RSQB", "_RPAR", "$END"]
    out.extend(_DESCRIBE[n] for n in order if n in names)
    return tuple(out)


def _join(expected: tuple[str, ...]) -> str:
    if len(expected) <= 1:
        return "".join(expected)
    return ", ".join(expected[:-1]) + " or " + expected[-1]


def _end_position(text: str) -> tuple[int, int]:
    lines = text.split("\n")
    return len(lines), len(lines[-1]) + 1


def _from_lark(err: UnexpectedInput, text: str, start: str) -> ParseError:
    from lark.exceptions import UnexpectedCharacters, UnexpectedToken

    if isinstance(err, UnexpectedToken):
        tok = err.token
        expected = _describe_expected(_accepts_at(err))
        if tok.type == "$END":
            line, column = _end_position(text)
            shown, snippet = "end of input", ""
        else:
            line, column = _pos(tok)
            shown, snippet = f"{str(tok)!r}", str(tok)
    elif isinstance(err, UnexpectedCharacters):
        line, column = err.line, err.column
        snippet = text[err.pos_in_stream] if 0 <= err.pos_in_stream < len(text) else ""
        shown = f"character {snippet!r}"
        expected = _describe_expected(_accepts_before(text[: err.pos_in_stream], start))
    else:  # UnexpectedEOF and future kinds
        line, column = _end_position(text)
        shown, snippet, expected = "end of input", "", ()
    reason = f"unexpected {shown}"
    if expected:
        reason += f"; expected {_join(expected)}"
    if isinstance(err, UnexpectedToken):
        reason += _reserved_hint(text, err.token)
    return ParseError(
        reason, line=line, column=column, text=snippet, expected=expected, source=text
    )


_OPERATOR_OF = {
    "true": "the constant true",
    "false": "the constant false",
    "X": "next, X p",
    "F": "eventually, F p",
    "G": "always, G p",
    "U": "until, p U q",
    "R": "release, p R q",
    "W": "weak until, p W q",
    "D": "the distribution eventuality, D[mu] a",
}


@cache
def _keyword_terminals() -> dict[str, str]:
    """Terminal name -> reserved word, for the grammar's keyword terminals."""
    return {
        t.name: t.pattern.value
        for t in tables.parser().terminals
        if t.pattern.type == "str" and t.pattern.value in RESERVED
    }


def _reserved_hint(text: str, tok: Token) -> str:
    """A note when the offending token, or the one before it, is a reserved word (a
    user who writes ``F (D & E)`` means propositions ``D`` and ``E``)."""
    from lark.exceptions import LarkError

    keywords = _keyword_terminals()
    word = keywords.get(tok.type)
    if word is None:
        end = len(text) if tok.type == "$END" or tok.start_pos is None else tok.start_pos
        previous = None
        try:
            for t in tables.parser().lex(text[:end]):
                previous = t
        except LarkError:
            return ""
        word = keywords.get(previous.type) if previous is not None else None
    if word == "W" and tok.type in ("LSQB", "LE"):
        return "; the weak until W takes no interval (p W q is p U q | G p)"
    if word is None:
        return ""
    return (f"; {word!r} is a reserved word ({_OPERATOR_OF[word]}) and cannot name a "
            "proposition")


def _accepts_at(err: UnexpectedToken) -> set[str]:
    """What the parser accepts where ``err`` happened, after any pending reductions
    (``err.expected`` lists only the terminals of the state the error was found in)."""
    try:
        ip = err.interactive_parser
        if ip is not None:
            return set(ip.accepts())
    except Exception:  # noqa: BLE001 - only used to phrase an error message
        pass
    return set(err.expected)


def _accepts_before(prefix: str, start: str) -> set[str]:
    """The terminals the parser accepts after ``prefix`` (which lexes and parses)."""
    try:
        ip = tables.parser().parse_interactive(prefix, start=start)
        ip.exhaust_lexer()
        return set(ip.accepts())
    except Exception:  # noqa: BLE001 - only used to phrase an error message
        return set()


# --------------------------------------------------------------------------- entry points


def _run(text: str, start: str) -> tuple[Tree, dict[int, object]]:
    """The parse tree of ``text`` and the value built for each of its nodes (by id)."""
    if not isinstance(text, str):
        raise TypeError(f"expected a str to parse, got {type(text).__name__}")
    from lark.exceptions import LarkError, UnexpectedInput

    try:
        tree = tables.parser().parse(text, start=start)
        return tree, _transform(tree, _Build(text))
    except ParseError:
        raise
    except UnexpectedInput as err:
        raise _from_lark(err, text, start) from None
    except RecursionError:
        raise _too_deep(text) from None
    except LarkError as err:  # pragma: no cover - defensive
        line, column = _end_position(text)
        raise ParseError(
            f"cannot parse: {err}".splitlines()[0], line=line, column=column, text="", source=text
        ) from None


def _transform(tree: Tree, builder: _Build) -> dict[int, object]:
    """Apply ``builder``'s rule methods bottom-up, iteratively (deep input must not
    overflow the Python stack); the value of every node, by ``id``."""
    from lark import Tree

    results: dict[int, object] = {}
    stack: list[tuple[Tree, bool]] = [(tree, False)]
    while stack:
        node, expanded = stack.pop()
        if not expanded:
            stack.append((node, True))
            for child in node.children:
                if isinstance(child, Tree):
                    stack.append((child, False))
            continue
        children = [results[id(ch)] if isinstance(ch, Tree) else ch for ch in node.children]
        method = getattr(builder, str(node.data))
        results[id(node)] = method(children)
    return results


def _too_deep(text: str) -> ParseError:
    return ParseError(
        f"formula nested too deeply (more than {MAX_DEPTH} levels)",
        line=1,
        column=1,
        text=text[:20],
        source=text,
    )


def parse(text: str) -> Formula:
    """Parse one MITLD formula; the result is built by the smart constructors, so it is
    in their simplified form and ``parse(str(f)) == f``.

    Raises :class:`ParseError` (with line and column) on any malformed input, including
    an empty interval ``[l,u]`` with ``l > u``, a distribution literal of the wrong shape
    and nesting deeper than :data:`MAX_DEPTH`.
    """
    return parse_source(text).formula


def parse_source(text: str) -> Source:
    """Parse one MITLD formula and keep what its text says beyond the simplified formula:
    every ``D[mu] a`` written (also one a constant absorbed, as in ``D[mu] a & false``)
    and where each subformula is written (see :mod:`mitld_lp.logic.source`).  Raises
    :class:`ParseError` as :func:`parse` does.

    A well-formed formula is read without lark (:mod:`mitld_lp.logic.plain_parse`, the
    same :class:`Source`); whatever that parser leaves, and a formula nested deeper than
    :data:`MAX_DEPTH`, goes to lark, which reports every error."""
    plain = plain_source(text) if isinstance(text, str) else None
    if plain is not None and not _too_deep_source(plain):
        return plain
    tree, built = _run(text, "start")
    result = built[id(tree)]
    assert isinstance(result, Formula)
    if formula_depth(result) > MAX_DEPTH:
        raise _too_deep(text)
    try:
        source = source_of(text, tree, built)
    except RecursionError:  # a deep operand that the simplification dropped
        raise _too_deep(text) from None
    if _too_deep_source(source):
        raise _too_deep(text)
    return source


def _too_deep_source(source: Source) -> bool:
    """Whether the formula of ``source``, or a law its text writes, nests deeper than
    :data:`MAX_DEPTH`."""
    return (formula_depth(source.formula) > MAX_DEPTH
            or any(formula_depth(site.dist) > MAX_DEPTH for site in source.laws))


def parse_distribution(text: str) -> DistSpec:
    """Parse a distribution as written inside ``D[...]``: a name (``mu1`` ->
    :class:`DistRef`) or a literal (``geometric(0.3)`` -> :class:`DistLiteral`)."""
    tree, built = _run(text, "dist_start")
    result = built[id(tree)]
    assert isinstance(result, DistRef | DistLiteral)
    return result
