"""How deep a PRISM expression is, found by a scan of the text before Storm parses it.

Storm's PRISM parser and the visitors that walk its expressions (substitution,
evaluation, printing) recurse once per level of an expression, in this process: an
expression nested deeply enough overflows the C++ stack and kills the process with no
message (stormpy 2.0 on an 8 MiB stack: a guard in 1,700 parentheses, a constant
``4-0-0-...`` of 2,000 terms; a label of 5,000 disjuncts is refused by Storm with an
unreadable message).  So the text is scanned first, and a statement deeper than
:data:`MAX_DEPTH` is refused with its line and column.

The scan bounds the depth of the tree Storm builds, without parsing: within one
statement (up to a ``;``, a bracket or a keyword such as ``endmodule``), a
parenthesised group's depth is ``1 + its operators + the deepest group or named
expression inside it``, and the statement's is its operators plus the deepest group or
named expression in it.  Every node on a path of the tree is
an operator of one of the groups the path crosses, so the tree is no deeper.  A
``formula`` or ``const`` is substituted where it is used, so its name counts as deep as
its definition.  Operators are counted generously (every ``&``, ``|``, ``!``, ``+``,
``-``, ``*``, ``/``, comparison, ``?``, ``:``, ``,`` and ``->``, also between a
command's updates), which only makes the bound larger.  The PRISM files of the QVBS
benchmarks reach at most 394 (wlan.6); the limit is well below where Storm fails.

:func:`check_text` reads a PRISM file as :func:`mitld_lp.worlds.prism.load_prism` hands
it to Storm only then: a regular file within the size ceiling, UTF-8, no expression
deeper than the limit.
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass
from pathlib import Path

from mitld_lp.worlds import WorldError

__all__ = ["MAX_DEPTH", "Deep", "ExpressionDepth", "check_text"]

MAX_DEPTH = 1000
"""The deepest PRISM expression read (see the module docstring for how it is counted)."""

_TOKEN = re.compile(
    r'//[^\n]*|"[^"\n]*"|[A-Za-z_][A-Za-z_0-9]*|[0-9.]+(?:[eE][-+]?[0-9]+)?'
    r"|<=>|=>|->|!=|<=|>=|[()&|!=<>+\-*/?:,;\[\]]"
)
_KEYWORDS = frozenset({  # words that end a statement without a ";" before them
    "formula", "const", "label", "global", "module", "endmodule", "rewards", "endrewards",
    "init", "endinit", "system", "endsystem", "player", "endplayer", "mdp", "dtmc", "ctmc",
    "pta", "pomdp", "smg", "nondeterministic", "probabilistic", "stochastic",
})


@dataclass(frozen=True, slots=True)
class Deep:
    """A statement deeper than the limit: how deep it was counted when the scan stopped
    (more than :data:`MAX_DEPTH`) and where it starts (``line`` and ``column`` from 1,
    in the text scanned)."""

    depth: int
    line: int
    column: int

    def message(self) -> str:
        return (f"an expression more than {MAX_DEPTH:,} levels deep (counting its operators "
                "and parentheses); Storm's parser can crash the process on deeper ones, so "
                f"at most {MAX_DEPTH:,} are read")


class ExpressionDepth:
    """The scan (module docstring), keeping the depth of every ``formula`` and ``const``
    it has seen, so that text scanned later (a label added to the file, a property over
    it) counts their names as deep as their definitions."""

    def __init__(self) -> None:
        self.named: dict[str, int] = {}

    def deepest(self, text: str) -> Deep | None:
        """The first statement of ``text`` deeper than :data:`MAX_DEPTH`, or None."""
        tokens = _TOKEN.findall(text)
        stack = [[0, 0]]  # per open group: its operators, its deepest inner part
        path = 0  # the operators of the open groups, plus one per group opened
        start = -1  # the token the statement began with
        named = self.named
        for k, token in enumerate(tokens):
            first = token[0]
            if first == "/" and token.startswith("//") or first == '"':
                continue
            if token in _KEYWORDS or token in ("[", "]"):  # a renaming's "[a=b, ...]" too
                depth = self._end(tokens, start, stack)
                if depth > MAX_DEPTH:
                    return _at(text, start, depth)
                stack, path = [[0, 0]], 0
                start = k if token in ("formula", "const") else -1
                continue
            if start < 0:
                start = k
            if first.isalpha() or first == "_":
                depth = named.get(token)
                if depth is not None and depth > stack[-1][1]:
                    stack[-1][1] = depth
            elif first.isdigit() or first == ".":
                continue
            elif token == "(":
                stack.append([0, 0])
                path += 1
            elif token == ")":
                if len(stack) > 1:
                    ops, inner = stack.pop()
                    stack[-1][1] = max(stack[-1][1], 1 + ops + inner)
                    path -= ops + 1
            elif token == ";":
                depth = self._end(tokens, start, stack)
                if depth > MAX_DEPTH:
                    return _at(text, start, depth)
                stack, path, start = [[0, 0]], 0, -1
            else:
                stack[-1][0] += 1
                path += 1
            if path > MAX_DEPTH:  # already deeper, whatever follows: stop here
                return _at(text, start, path)
        depth = self._end(tokens, start, stack)
        return _at(text, start, depth) if depth > MAX_DEPTH else None

    def _end(self, tokens: list[str], start: int, stack: list[list[int]]) -> int:
        """The depth of the statement from token ``start`` (-1: none), recorded for a
        definition ``formula NAME = ...`` or ``const [TYPE] NAME = ...``."""
        while len(stack) > 1:  # unclosed parentheses (Storm reports them): closed here
            ops, inner = stack.pop()
            stack[-1][1] = max(stack[-1][1], 1 + ops + inner)
        depth = stack[0][0] + stack[0][1]
        if start >= 0 and tokens[start] in ("formula", "const"):
            rest = tokens[start + 1 : start + 4]
            if rest[:1] and rest[0] in ("int", "double", "bool"):
                rest = rest[1:]
            if len(rest) >= 2 and rest[1] == "=" and (rest[0][0].isalpha() or rest[0][0] == "_"):
                self.named[rest[0]] = depth - 1  # its "=" is no operator of the tree
        return depth


def _at(text: str, token: int, depth: int) -> Deep:
    """The :class:`Deep` record of the statement that begins at token ``token``."""
    m = next(itertools.islice(_TOKEN.finditer(text), max(token, 0), None), None)
    offset = 0 if m is None else m.start()
    line = text.count("\n", 0, offset) + 1
    return Deep(depth, line, offset - (text.rfind("\n", 0, offset) + 1) + 1)


def check_text(path: Path, where: str, depth: ExpressionDepth) -> None:
    """Refuse a file that is not UTF-8 text (naming the first bad byte's place) or that
    holds an expression deeper than Storm's parser can take (its place and the limit;
    ``depth`` keeps its formulas' depths)."""
    from mitld_lp.files import rules as file_rules

    try:  # a regular file, bounded, before Storm reads it
        data = file_rules.read_bytes(path)
    except file_rules.InputFileError as exc:  # says what it is: a FIFO, a folder, too large
        raise WorldError(f"{where}: {exc.strerror}") from None
    except FileNotFoundError:
        raise WorldError(f"{where}: no such PRISM file") from None
    except OSError as exc:
        raise WorldError(f"{where}: cannot read: {exc.strerror or exc}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise WorldError(
            f"{where}:{line}:{column}: not UTF-8 text (byte 0x{data[exc.start]:02x}); "
            "a PRISM file is UTF-8"
        ) from None
    deep = depth.deepest(text)
    if deep is not None:
        raise WorldError(f"{where}:{deep.line}:{deep.column}: {deep.message()}")
