"""Reference evaluator: three-valued truth of a formula on a finite discrete-time trace.

A trace ``w = w_0 w_1 ... w_{n-1}`` (each ``w_i`` the set of propositions true at step
``i``) is read as the known prefix of an infinite run whose later letters are unknown.
The verdict is computed *compositionally* in Kleene's strong three-valued logic
(``FALSE < UNKNOWN < TRUE``; ``&`` is min, ``|`` is max, ``!`` swaps TRUE and FALSE):

* ``true``/``false`` have their value at every step, inside the trace or beyond it;
* a proposition ``a`` at step ``i < n`` is TRUE iff ``a in w_i``; at ``i >= n`` UNKNOWN;
* ``X a`` at ``i`` is ``a`` at ``i + 1``;
* ``a U[l,u] b`` at ``t`` is  ``OR_{j = t+l}^{t+u} ( b@j  AND  AND_{i = t}^{j-1} a@i )``
  (unbounded ``U``: ``j`` ranges over all ``j >= t``);
* ``a R[l,u] b == !(!a U[l,u] !b)``, i.e.
  ``AND_{j = t+l}^{t+u} ( b@j  OR  OR_{i = t}^{j-1} a@i )``;
* ``D[mu] a`` is read as ``F a == true U a``.

So a verdict is TRUE (FALSE) only when the known prefix decides the formula through the
operators' definitions; it is then the truth value on every infinite extension.  This
is the reading the automaton is tested against: it accepts (rejects) when progression
by the trace's letters reaches ``true`` (``false``), and progression folds constants in
exactly these Kleene steps.  It is not a tautology checker: ``p | !p`` beyond the trace
end is UNKNOWN, as is its progression.

:func:`holds_lasso` is the two-valued truth on an infinite *ultimately periodic* word
``u v v v ...`` (a lasso): exactly the semantics of the operators on infinite runs, the
reference for safety and obligation formulas, which a finite prefix cannot always
decide.

Beyond the trace every letter is unknown, so every subformula has one value at all
steps ``i >= n``; the evaluator computes that value once per subformula, which makes the
infinite windows of unbounded operators finite.  Values are memoised per (subformula,
step): each subformula is evaluated at all steps of the trace once, bottom-up.
"""

from __future__ import annotations

from collections.abc import Sequence, Set
from enum import Enum

from mitld_lp.logic.syntax import (
    TRUE,
    And,
    Const,
    Dist,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
)

__all__ = ["Verdict", "holds", "holds_lasso", "Trace"]

Trace = Sequence[Set[str]]

# Kleene values as integers: conjunction is min, disjunction max, negation 2 - v.
_F, _U, _T = 0, 1, 2


class Verdict(Enum):
    """A three-valued verdict on a finite trace."""

    FALSE = 0
    UNKNOWN = 1
    TRUE = 2

    def __bool__(self) -> bool:
        raise TypeError("a Verdict is three-valued; compare it with Verdict.TRUE")


def holds(f: Formula, trace: Trace, t: int = 0) -> Verdict:
    """The Kleene three-valued truth of ``f`` at step ``t`` of the finite ``trace`` (see
    the module docstring).  ``t`` may lie beyond the end of the trace (every proposition
    is then unknown).  Raises ``ValueError`` for a negative ``t``."""
    if t < 0:
        raise ValueError(f"step must be >= 0, got {t}")
    values, beyond = _Evaluator(trace).values(f)
    return Verdict(values[t] if t < len(values) else beyond)


class _Evaluator:
    """Vectors of Kleene values per subformula: one per step of the trace, plus the
    common value at every step beyond its end.  Keyed by ``id`` (subformulas are alive
    while the root is, and hashing a deep frozen node is linear in its size)."""

    def __init__(self, trace: Trace) -> None:
        self.trace = [frozenset(letter) for letter in trace]
        self.n = len(self.trace)
        self.memo: dict[int, tuple[list[int], int]] = {}

    def values(self, f: Formula) -> tuple[list[int], int]:
        key = id(f)
        hit = self.memo.get(key)
        if hit is None:
            hit = self._compute(f)
            self.memo[key] = hit
        return hit

    def _compute(self, f: Formula) -> tuple[list[int], int]:
        n = self.n
        match f:
            case Const(v):
                c = _T if v else _F
                return [c] * n, c
            case Prop(name):
                return [_T if name in letter else _F for letter in self.trace], _U
            case Not(a):
                va, ba = self.values(a)
                return [2 - x for x in va], 2 - ba
            case And(args):
                vs = [self.values(a) for a in args]
                return [min(v[0][i] for v in vs) for i in range(n)], min(v[1] for v in vs)
            case Or(args):
                vs = [self.values(a) for a in args]
                return [max(v[0][i] for v in vs) for i in range(n)], max(v[1] for v in vs)
            case Next(a):
                va, ba = self.values(a)
                return va[1:] + [ba] if n else [], ba
            case Until(left, right, iv):
                return self._until(self.values(left), self.values(right), iv)
            case Release(left, right, iv):
                (vl, bl), (vr, br) = self.values(left), self.values(right)
                vals, beyond = self._until(
                    ([2 - x for x in vl], 2 - bl), ([2 - x for x in vr], 2 - br), iv
                )
                return [2 - x for x in vals], 2 - beyond
            case Dist(_, a):
                return self._until(self.values(TRUE), self.values(a), None)
            case _:
                raise TypeError(f"not a formula: {f!r}")

    def _until(
        self,
        left: tuple[list[int], int],
        right: tuple[list[int], int],
        iv: Interval | None,
    ) -> tuple[list[int], int]:
        """``left U[iv] right`` at every step.  For a witness step ``j`` the term is
        ``right@j AND left@t..j-1``; all ``j > n`` give the same term (every value there
        is the beyond-value), so one term stands for them."""
        n = self.n
        (vl, bl), (vr, br) = left, right
        lo = 0 if iv is None else iv.lo
        hi = None if iv is None else iv.hi
        out: list[int] = []
        for t in range(n):
            last = n + 1 if hi is None else min(t + hi, n + 1)
            acc, prefix = _F, _T  # prefix: AND of left@i for i in [t, j)
            for j in range(t, last + 1):
                if j == n + 1:
                    # Stands for every witness j > n, and the window reaches past n here
                    # (last == n + 1), so it holds at least one: right is br there and the
                    # prefix already includes bl (added at j = n).
                    acc = max(acc, min(br, prefix))
                    break
                if j >= t + lo:
                    acc = max(acc, min(vr[j] if j < n else br, prefix))
                if acc == _T:
                    break
                prefix = min(prefix, vl[j] if j < n else bl)
                if prefix == _F:
                    break
            out.append(acc)
        # beyond the trace: j = t gives right (if lo == 0); every j > t gives
        # right AND left (Kleene conjunction is idempotent).
        beyond = _F
        if lo == 0:
            beyond = br
        if hi is None or hi >= 1:
            beyond = max(beyond, min(br, bl))
        return out, beyond


def holds_lasso(f: Formula, prefix: Trace, loop: Trace) -> bool:
    """Whether ``f`` holds at step 0 of the infinite word ``prefix loop loop loop ...``.

    The word has ``n = len(prefix) + len(loop)`` distinct positions; the step after the
    last one is the first step of ``loop``.  Every subformula is evaluated at each
    position from its definition:

    * ``X a`` at ``i`` is ``a`` at the next position;
    * ``a U b`` is the least solution of ``v(i) = b(i) | (a(i) & v(next(i)))`` and
      ``a R b`` the greatest solution of ``v(i) = b(i) & (a(i) | v(next(i)))`` (the
      strict until: ``a`` is needed before the witness of ``b``, not at it);
    * ``a U[l,u] b`` at ``i`` is ``OR_{k=l}^{u} (b@i+k AND AND_{m<k} a@i+m)`` and its dual
      for ``R[l,u]``, counting steps along the lasso;
    * ``D[mu] a`` reads as ``F a``.

    Raises ``ValueError`` for an empty ``loop``."""
    if not loop:
        raise ValueError("the loop of a lasso must have at least one letter")
    return _Lasso([*prefix, *loop], len(prefix)).values(f)[0]


class _Lasso:
    """Boolean vectors over the positions of a lasso, per subformula (by ``id``)."""

    def __init__(self, word: list, start: int) -> None:
        self.word = [frozenset(letter) for letter in word]
        self.n = len(self.word)
        self.next = [*range(1, self.n), start]
        self.memo: dict[int, list[bool]] = {}

    def values(self, f: Formula) -> list[bool]:
        hit = self.memo.get(id(f))
        if hit is None:
            hit = self.memo[id(f)] = self._compute(f)
        return hit

    def _compute(self, f: Formula) -> list[bool]:
        match f:
            case Const(v):
                return [v] * self.n
            case Prop(name):
                return [name in letter for letter in self.word]
            case Not(a):
                return [not x for x in self.values(a)]
            case And(args):
                vs = [self.values(a) for a in args]
                return [all(v[i] for v in vs) for i in range(self.n)]
            case Or(args):
                vs = [self.values(a) for a in args]
                return [any(v[i] for v in vs) for i in range(self.n)]
            case Next(a):
                va = self.values(a)
                return [va[j] for j in self.next]
            case Until(left, right, iv):
                return self._until(self.values(left), self.values(right), iv)
            case Release(left, right, iv):
                vl, vr = self.values(left), self.values(right)
                dual = self._until([not x for x in vl], [not x for x in vr], iv)
                return [not x for x in dual]
            case Dist(_, a):
                return self._until([True] * self.n, self.values(a), None)
            case _:
                raise TypeError(f"not a formula: {f!r}")

    def _until(self, vl: list[bool], vr: list[bool], iv: Interval | None) -> list[bool]:
        n, nxt = self.n, self.next
        if iv is None:  # least fixpoint, from all-false; each round settles one more step
            out = [False] * n
            changed = True
            while changed:
                changed = False
                for i in range(n):
                    if not out[i] and (vr[i] or (vl[i] and out[nxt[i]])):
                        out[i] = changed = True
            return out
        out = []
        for i in range(n):
            j, found = i, False  # left held on the steps i .. before j
            for k in range(iv.hi + 1):
                if k >= iv.lo and vr[j]:
                    found = True
                    break
                if not vl[j]:
                    break
                j = nxt[j]
            out.append(found)
        return out
