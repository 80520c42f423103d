"""The nesting depth of a formula, which the parser bounds
(:data:`mitld_lp.logic.parser.MAX_DEPTH`)."""

from __future__ import annotations

from mitld_lp.logic.syntax import And, Dist, Formula, Next, Not, Or, Release, Until

__all__ = ["formula_depth"]


def formula_depth(f: Formula) -> int:
    """Nesting depth of ``f`` (a proposition has depth 1), computed without recursion.

    The smart constructors share subformulas (``a W b`` holds ``b`` twice), so ``f`` is a
    DAG whose paths can be exponentially many: a node already reached at a depth at
    least ``d`` is not walked again (what lies below it adds the same either way)."""
    best = 0
    seen: dict[int, int] = {}
    stack: list[tuple[Formula, int]] = [(f, 1)]
    while stack:
        g, d = stack.pop()
        if seen.get(id(g), 0) >= d:
            continue
        seen[id(g)] = d
        best = max(best, d)
        match g:
            case Not(a) | Next(a) | Dist(_, a):
                stack.append((a, d + 1))
            case And(args) | Or(args):
                stack.extend((a, d + 1) for a in args)
            case Until(left, right, _) | Release(left, right, _):
                stack.append((left, d + 1))
                stack.append((right, d + 1))
    return best
