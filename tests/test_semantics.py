"""The reference evaluator: every operator on hand-worked traces (expected verdicts worked
out from the definitions in mitld_lp.logic.semantics), and a cross-check against an independent
brute-force two-valued evaluator on infinite extensions of the trace."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp.logic.fragment import horizon
from mitld_lp.logic.parser import parse
from mitld_lp.logic.semantics import Verdict, holds, holds_lasso
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
from mitld_lp.testing.hypothesis import formulas, traces

T, F, U = Verdict.TRUE, Verdict.FALSE, Verdict.UNKNOWN

#            step: 0     1      2      3
W = (frozenset(), frozenset({"p"}), frozenset({"q"}), frozenset())


# Each row: formula, step, verdict, and the reasoning from the definition.
HAND = [
    ("p", 0, F),  # p not in w0
    ("p", 1, T),
    ("p", 4, U),  # beyond the trace
    ("true", 9, T),  # constants are known everywhere
    ("!p", 1, F),
    ("!p", 5, U),
    ("X p", 0, T),  # p at 1
    ("X p", 3, U),  # p at 4 is unknown
    ("X X q", 0, T),  # q at 2
    ("X X X X p", 0, U),  # p at 4
    ("!X p", 1, T),  # p at 2 false
    # bounded eventually
    ("F[0,2] q", 0, T),  # q at 2
    ("F[0,1] q", 0, F),  # q neither at 0 nor 1
    ("F[1,1] p", 0, T),  # exactly step 1
    ("F[2,3] p", 0, F),  # steps 2, 3: no p
    ("F[3,5] q", 0, U),  # step 3 no; 4, 5 unknown
    ("F[2,3] true", 3, T),  # some step in [5,6] has true
    # until, bounded and unbounded
    ("p U q", 1, T),  # j=2: q@2 and p@1
    ("p U q", 0, F),  # q first at 2 but p@0 fails, and every later j needs p@0
    ("q U p", 2, F),  # j=2: p@2 no; j=3: p@3 no (q@2 ok); j>=4 need q@3: no
    ("!q U p", 0, T),  # j=1: p@1, !q@0
    ("!p U r", 2, U),  # r never in the trace; !p@2, !p@3 hold; later unknown
    ("p U[1,2] q", 1, T),  # j in [2,3]: j=2 q@2, p@1
    ("p U[2,3] q", 1, F),  # j=3: q@3 no; j=4 needs p@2: no
    ("true U[2,3] q", 1, U),  # j=3 no, j=4 unknown
    ("p U[0,0] q", 2, T),  # j=2 only: q@2
    ("p U[0,0] q", 0, F),  # j=0 only: q@0 no; p never consulted
    ("false U q", 2, T),  # only j=t possible
    ("false U q", 0, F),
    ("false U q", 4, U),
    # release, bounded and unbounded
    ("q R p", 1, F),  # j=1 p ok; j=2: p@2 no and q@1 no
    ("p R[0,1] !q", 0, T),  # !q at 0 and 1
    ("p R[1,3] !q", 0, T),  # j=1 ok; j=2: !q@2 no but p@1; j=3 ok
    ("p R[1,3] !q", 1, T),  # j=2: p@1 releases it, and j=3.. released too
    ("q R[0,5] !p", 2, T),  # j=2 !p@2 ok; every j>=3 released by q@2
    ("!p R[0,2] !q", 0, T),  # j=0,1: !q ok; j=2: !q@2 fails but !p@0 releases it
    ("r R !r", 0, U),  # !r at every known step, unknown later
    ("false R[0,1] !q", 1, F),  # j=1: !q@1 ok; j=2: !q@2 fails, nothing releases
    # always
    ("G[0,1] !q", 0, T),  # !q at 0, 1
    ("G[0,2] !q", 0, F),  # q at 2
    ("G[0,1] p", 3, F),  # p@3 no
    ("G[1,1] p", 0, T),
    ("G[0,3] !r", 0, T),  # r nowhere in steps 0..3
    ("G[0,4] !r", 0, U),  # step 4 unknown
    ("!F[0,5] p", 0, F),  # p at 1
    ("F p", 2, U),  # no p at 2, 3; later unknown
    ("F p", 0, T),
    ("G p", 0, F),  # p@0 no
    ("G !r", 0, U),
    # nesting
    ("F[1,2] G[0,1] !p", 0, T),  # j=1: !p@1 no; j=2: !p@2, !p@3 yes
    ("F[0,1] (p & X q)", 0, T),  # j=1: p@1, q@2
    ("G[0,1] (p -> X q)", 0, T),  # j=0: !p@0; j=1: q@2
    ("G[0,3] (q -> X p)", 0, F),  # j=2: q@2 and p@3 no
    ("G[0,1] (q -> X p)", 2, F),  # j=2: q@2, p@3 no
    ("G[0,1] (q -> X p)", 3, U),  # j=3: !q@3 ok; j=4: q@4 unknown
    ("F[0,1] p U[1,1] q", 0, F),  # only j=1, and q@1 fails
    ("X (p U[0,1] q)", 0, T),  # at 1: j=1 q no; j=2 q@2 and p@1
    ("p U[1,3] (q & X !q)", 0, F),  # p@0 fails for j>=1
    ("(F[0,1] p) U[1,2] q", 0, T),  # j=2: q@2; F[0,1]p at 0 (p@1) and at 1 (p@1)
    ("F[0,9] r | q", 2, T),
    ("F[0,9] r & q", 2, U),  # unknown & true
    ("F[0,1] r & q", 2, F),
    # distribution eventuality reads as F
    ("D[mu] q", 0, T),
    ("D[mu] q", 3, U),
    ("D[geometric(0.5)] r", 0, U),
    ("!D[mu] q", 0, F),
]


@pytest.mark.parametrize(("text", "t", "verdict"), HAND)
def test_hand_worked(text: str, t: int, verdict: Verdict) -> None:
    assert holds(parse(text), W, t) is verdict


@pytest.mark.parametrize(
    ("text", "verdict"),
    [
        *[(text, U) for text in ("p", "!p", "p | !p", "G[0,2] p", "F[0,2] p", "p U q")],
        *[(text, T) for text in ("true", "X true", "F[2,3] true")],
        ("false", F),
    ],
)
def test_empty_trace(text: str, verdict: Verdict) -> None:
    assert holds(parse(text), ()) is verdict


def test_raw_nodes_and_constants_beyond_the_trace() -> None:
    # F[2,3] true is not simplified by the constructor; on any trace it is true.
    assert holds(Until(TRUE, TRUE, Interval(2, 3)), [frozenset()], 0) is T
    assert holds(Next(Const(False)), [], 0) is F


def test_paper_formula_on_traces() -> None:
    f = parse("(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))")
    # bus 1 at step 1, station A reached at step 3 (within [1, 4]): decided true
    assert holds(f, [set(), {"b1"}, set(), {"A"}]) is T
    # bus 1 at step 1, A not reached in steps 1..4; bus 1 never comes again in the
    # trace, bus 2 never seen: both disjuncts still open -> unknown
    assert holds(f, [set(), {"b1"}, set(), set(), set(), set()]) is U
    # reaching B without bus 2 does not decide anything yet
    assert holds(f, [{"B"}, {"B"}]) is U


def test_bad_step() -> None:
    with pytest.raises(ValueError):
        holds(parse("p"), [], -1)


def test_verdict_is_not_a_bool() -> None:
    with pytest.raises(TypeError):
        bool(Verdict.TRUE)


# --------------------------------------------------------------------------- cross-check


def ev2(f: Formula, w: list[frozenset[str]], t: int) -> bool:
    """Two-valued truth at step ``t`` on the infinite word w + (last letter of w) forever,
    straight from the definitions (:func:`brute_lasso`)."""
    return brute_lasso(f, w[:-1], w[-1:], t)


def _as_bool(v: Verdict) -> bool:
    assert v is not U
    return v is T


@given(
    formulas(max_depth=5, max_bound=4, with_dist=True),
    traces(min_len=0, max_len=12),
    st.lists(traces(min_len=1, max_len=6), min_size=1, max_size=3),
)
def test_decided_verdicts_hold_on_every_extension(
    f: Formula, w: tuple[frozenset[str], ...], tails: list[tuple[frozenset[str], ...]]
) -> None:
    """Soundness: TRUE/FALSE on a prefix is the truth on any infinite continuation, and
    extending the trace never changes a decided verdict."""
    for t in range(len(w) + 1):
        v = holds(f, w, t)
        for tail in tails:
            longer = list(w) + list(tail)
            if v is not U:
                assert ev2(f, longer, t) == _as_bool(v)
                assert holds(f, longer, t) is v


@given(
    formulas(max_depth=5, max_bound=4).filter(lambda g: horizon(g) is not None),
    st.data(),
)
def test_bounded_formulas_match_the_two_valued_evaluator(f: Formula, data: st.DataObject) -> None:
    """Completeness on decided traces: with horizon + 1 letters after step t, the verdict
    at t is decided and equals the two-valued truth."""
    h = horizon(f)
    assert h is not None
    w = data.draw(traces(min_len=h + 1, max_len=h + 8))
    for t in range(len(w) - h):
        assert _as_bool(holds(f, w, t)) == ev2(f, list(w), t)


@given(formulas(max_depth=5, max_bound=6), traces(min_len=15, max_len=20))
def test_depth_five_on_length_twenty_is_decided_and_monotone(
    f: Formula, w: tuple[frozenset[str], ...]
) -> None:
    """A bounded formula is decided wherever its horizon fits in the trace, and a verdict
    decided on a prefix is the verdict on the whole trace (the strong Kleene reading only
    gains information as letters arrive)."""
    h = horizon(f)
    for t in range(0, len(w) + 2, 5):
        full = holds(f, w, t)
        assert isinstance(full, Verdict)
        if h is not None and t + h < len(w):
            assert full is not U, (str(f), t, h)
        for cut in (t, t + 3, len(w) - 1):
            part = holds(f, w[:cut], t)
            if part is not U:
                assert part is full, (str(f), t, cut)


# --------------------------------------------------------------------------- lassos

E_, P_, Q_ = frozenset(), frozenset({"p"}), frozenset({"q"})

# formula, prefix, loop, truth on prefix loop loop ..., worked out from the definitions
LASSO_HAND = [
    ("G p", [], [P_], True),
    ("G p", [P_, P_], [P_, E_], False),  # p fails at the second step of every loop pass
    ("F p", [E_], [E_], False),
    ("F p", [E_], [E_, E_, P_], True),
    ("G F p", [], [E_, P_], True),
    ("G F p", [P_], [E_], False),
    ("F G p", [], [E_, P_], False),
    ("F G p", [E_, E_], [P_], True),
    ("p U q", [P_, P_], [Q_], True),  # q at step 2, p at 0 and 1
    ("p U q", [P_, E_], [Q_], False),  # p missing at step 1, before the only q
    ("p U q", [], [Q_], True),  # q at once: nothing asked of p
    ("p W q", [], [P_], True),  # q never comes, p forever
    ("p W q", [P_], [E_], False),
    ("p W q", [E_], [Q_], False),  # neither p nor q at step 0
    ("p W q", [Q_], [E_], True),  # q at once
    ("X X p", [E_], [E_, P_], True),  # steps: E_ E_ P_ E_ P_ ...
    ("X X X p", [E_], [E_, P_], False),
    ("F[2,2] p", [E_], [E_, P_], True),
    ("F[3,4] p", [E_], [P_, E_, E_], True),  # steps 3, 4 are E_, P_ (wrapped once)
    ("G[1,3] !p", [P_], [E_, E_, E_, P_], True),
    ("G (p -> F[0,1] q)", [], [P_, Q_, E_], True),
    ("G (p -> F[0,1] q)", [], [P_, E_, Q_], False),
    ("p R q", [Q_], [Q_, E_], False),  # q fails at step 2 and no p released it before
    ("!p R q", [Q_], [Q_, E_], True),  # !p at step 0 releases q from step 1 on
    ("D[mu] q", [E_], [E_, Q_], True),
]


@pytest.mark.parametrize(("text", "prefix", "loop", "truth"), LASSO_HAND)
def test_lasso_hand_worked(text: str, prefix: list, loop: list, truth: bool) -> None:
    assert holds_lasso(parse(text), prefix, loop) is truth


def test_lasso_needs_a_loop() -> None:
    with pytest.raises(ValueError, match="at least one letter"):
        holds_lasso(parse("p"), [P_], [])


def brute_lasso(f: Formula, prefix: list, loop: list, t: int = 0) -> bool:
    """Truth at step ``t`` of ``prefix loop loop ...`` with the quantifiers of the
    definitions written out: an unbounded witness is searched up to
    ``len(prefix) + len(loop)`` steps ahead (a first witness further away would repeat
    one period earlier)."""
    k, m = len(prefix), len(loop)

    def letter(i: int) -> frozenset[str]:
        return frozenset(prefix[i] if i < k else loop[(i - k) % m])

    def canon(i: int) -> int:  # positions with the same future
        return i if i < k else k + (i - k) % m

    cache: dict[tuple[int, int], bool] = {}

    def go(g: Formula, i: int) -> bool:
        key = (id(g), canon(i))
        if key in cache:
            return cache[key]
        match g:
            case Const(v):
                out = v
            case Prop(name):
                out = name in letter(i)
            case Not(a):
                out = not go(a, i)
            case And(args):
                out = all(go(a, i) for a in args)
            case Or(args):
                out = any(go(a, i) for a in args)
            case Next(a):
                out = go(a, i + 1)
            case Dist(_, a):
                out = any(go(a, j) for j in range(i, i + k + m + 1))
            case Until(a, b, iv):
                js = range(i, i + k + m + 1) if iv is None else range(i + iv.lo, i + iv.hi + 1)
                out = any(go(b, j) and all(go(a, x) for x in range(i, j)) for j in js)
            case Release(a, b, iv):
                js = range(i, i + k + m + 1) if iv is None else range(i + iv.lo, i + iv.hi + 1)
                out = all(go(b, j) or any(go(a, x) for x in range(i, j)) for j in js)
            case _:
                raise TypeError(g)
        cache[key] = out
        return out

    return go(f, t)


@given(
    formulas(max_depth=5, max_bound=4, with_dist=True),
    traces(min_len=0, max_len=5),
    traces(min_len=1, max_len=4),
)
def test_lasso_matches_the_quantifiers(f: Formula, prefix, loop) -> None:
    assert holds_lasso(f, prefix, loop) == brute_lasso(f, list(prefix), list(loop))


@given(
    formulas(max_depth=5, max_bound=4),
    traces(min_len=0, max_len=4),
    traces(min_len=1, max_len=4),
    st.integers(1, 3),
)
def test_lasso_agrees_with_decided_kleene_verdicts(f: Formula, prefix, loop, passes) -> None:
    """A prefix the three-valued reading decides decides every infinite extension."""
    v = holds(f, list(prefix) + list(loop) * passes)
    if v is not U:
        assert holds_lasso(f, prefix, loop) == (v is T)
