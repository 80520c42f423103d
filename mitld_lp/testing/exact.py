"""Exact reachability in fractions for tests: an independent route (no solver of the
package) to the values the solvers bracket."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from fractions import Fraction

__all__ = ["chain_values"]


def chain_values(step: Mapping[int, Mapping[int, Fraction]] | Sequence[Mapping[int, Fraction]],
                 maybe: list[int],
                 goal: int | Collection[int]) -> dict[int, Fraction]:
    """The probability of reaching ``goal`` (a state, or a set of states) from each
    state of ``maybe`` in the Markov chain ``step`` (state -> successor -> probability):
    ``x = P x + b`` on ``maybe`` (every state of it reaches the goal; successors outside
    it count 0) by Gauss--Jordan elimination in fractions."""
    goals = {goal} if isinstance(goal, int) else set(goal)
    at = {s: i for i, s in enumerate(maybe)}
    m = len(maybe)
    a = [[Fraction(int(i == j)) for j in range(m)] + [Fraction(0)] for i in range(m)]
    for s in maybe:
        for t, p in step[s].items():
            if t in goals:
                a[at[s]][m] += p
            elif t in at:
                a[at[s]][at[t]] -= p
    for col in range(m):
        pivot = next(r for r in range(col, m) if a[r][col] != 0)
        a[col], a[pivot] = a[pivot], a[col]
        inv = 1 / a[col][col]
        a[col] = [v * inv for v in a[col]]
        for r in range(m):
            if r != col and a[r][col] != 0:
                f = a[r][col]
                a[r] = [v - f * w for v, w in zip(a[r], a[col], strict=True)]
    return {s: a[at[s]][m] for s in maybe}
