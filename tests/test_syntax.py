"""The AST's smart constructors: simplification laws, structural invariants, and that the
simplified formula means what the unsimplified operator means (checked by a brute-force
evaluator written here, independently of mitld_lp.logic.semantics)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mitld_lp.logic.syntax import (
    FALSE,
    TRUE,
    And,
    Const,
    Dist,
    DistLiteral,
    DistRef,
    Formula,
    Interval,
    Next,
    Not,
    Or,
    Prop,
    Release,
    Until,
    always,
    atoms,
    conj,
    disj,
    dist,
    eventually,
    implies,
    neg,
    nxt,
    release,
    subformulas,
    until,
)
from mitld_lp.testing.hypothesis import formulas, intervals, traces

p, q, r = Prop("p"), Prop("q"), Prop("r")
FS = formulas(max_depth=3, max_bound=4)
TRACES = traces(("p", "q", "r"), min_len=1, max_len=8)


# --------------------------------------------------------------------------- brute force


def brute(f: Formula, w: tuple[frozenset[str], ...], t: int = 0) -> bool:
    """Two-valued truth at step t of the infinite trace w_0 .. w_{n-1} w_{n-1} w_{n-1} ...

    Every subformula has one value at all steps >= n - 1 (the suffix from there is the
    same), so a witness j of an unbounded until can be looked for up to max(t, n) + 1:
    the term for any later j equals that one.
    """
    memo: dict[tuple[int, int], bool] = {}
    n = len(w)

    def at(g: Formula, i: int) -> bool:
        key = (id(g), i)
        if key not in memo:
            memo[key] = ev(g, i)
        return memo[key]

    def ev(g: Formula, i: int) -> bool:
        if isinstance(g, Const):
            return g.value
        if isinstance(g, Prop):
            return g.name in w[min(i, n - 1)]
        if isinstance(g, Not):
            return not at(g.arg, i)
        if isinstance(g, And):
            return all(at(a, i) for a in g.args)
        if isinstance(g, Or):
            return any(at(a, i) for a in g.args)
        if isinstance(g, Next):
            return at(g.arg, i + 1)
        if isinstance(g, Dist):
            return any(at(g.arg, j) for j in range(i, max(i, n) + 2))
        if isinstance(g, Until | Release):
            lo, hi = (
                (0, max(i, n) + 1 - i) if g.interval is None else (g.interval.lo, g.interval.hi)
            )
            window = range(i + lo, i + hi + 1)
            if isinstance(g, Until):
                return any(
                    at(g.right, j) and all(at(g.left, k) for k in range(i, j)) for j in window
                )
            return all(at(g.right, j) or any(at(g.left, k) for k in range(i, j)) for j in window)
        raise TypeError(g)

    return at(f, t)


def positions(w: tuple[frozenset[str], ...]) -> range:
    return range(len(w) + 2)


# --------------------------------------------------------------------------- laws


@given(FS)
def test_conj_disj_units_and_zeros(a: Formula) -> None:
    assert conj(a, TRUE) == a
    assert conj(TRUE, a) == a
    assert conj(a, FALSE) == FALSE
    assert conj(FALSE, a) == FALSE
    assert disj(a, FALSE) == a
    assert disj(a, TRUE) == TRUE
    assert conj() == TRUE
    assert disj() == FALSE
    assert conj(a) == a
    assert disj(a) == a


@given(FS, FS, FS)
def test_flattening_is_associative_and_idempotent(a: Formula, b: Formula, c: Formula) -> None:
    for op, kind in ((conj, And), (disj, Or)):
        left, right = op(op(a, b), c), op(a, op(b, c))
        assert left == op(a, b, c) == right
        assert op(left) == left
        assert op(a, a) == a
        assert op(left, left) == left
        if isinstance(left, kind):
            assert all(not isinstance(x, kind | Const) for x in left.args)
            assert len(left.args) >= 2
            assert len(set(left.args)) == len(left.args)


@given(FS)
def test_double_negation_and_constants(a: Formula) -> None:
    assert neg(neg(a)) == a
    assert neg(TRUE) == FALSE and neg(FALSE) == TRUE
    assert nxt(TRUE) == TRUE and nxt(FALSE) == FALSE
    assert implies(a, q) == disj(neg(a), q)
    assert implies(FALSE, a) == TRUE
    assert implies(TRUE, a) == a


@given(FS, FS, intervals(5))
def test_until_release_absorption(a: Formula, b: Formula, iv: Interval) -> None:
    assert until(a, FALSE, iv) == FALSE
    assert until(a, FALSE) == FALSE
    assert until(a, TRUE) == TRUE
    assert release(a, TRUE, iv) == TRUE
    assert release(a, FALSE) == FALSE
    if iv.lo == 0:
        assert until(a, TRUE, iv) == TRUE
        assert release(a, FALSE, iv) == FALSE
    else:  # F[l,u] true with l > 0 is true on infinite traces but is kept as a node
        assert until(a, TRUE, iv) == Until(a, TRUE, iv)
    assert eventually(b, iv) == until(TRUE, b, iv)
    assert always(b, iv) == neg(eventually(neg(b), iv))


@given(FS)
def test_constructed_formulas_are_in_simplified_form(f: Formula) -> None:
    for g in subformulas(f):
        if isinstance(g, Not):
            assert not isinstance(g.arg, Not | Const)
        if isinstance(g, Next):
            assert not isinstance(g.arg, Const)
        if isinstance(g, And | Or):
            assert len(g.args) >= 2
            assert not any(isinstance(x, type(g) | Const) for x in g.args)
        if isinstance(g, Until):
            assert g.right != FALSE
        if isinstance(g, Release):
            assert g.right != TRUE


def test_interval_validation() -> None:
    assert Interval(0, 0) == Interval(0, 0)
    with pytest.raises(ValueError, match="exceeds"):
        Interval(3, 1)
    with pytest.raises(ValueError, match=">= 0"):
        Interval(-1, 2)
    with pytest.raises(ValueError, match="integer"):
        Interval(True, 2)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="integer"):
        Interval(0, 1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        until(p, q, (2, 1))


def test_constructors_reject_non_formulas() -> None:
    with pytest.raises(TypeError):
        conj(p, "q")  # type: ignore[arg-type]


def test_operator_overloads() -> None:
    assert (p & q) == conj(p, q)
    assert (p | q) == disj(p, q)
    assert ~p == Not(p)
    assert (p >> q) == disj(Not(p), q)


def test_atoms_and_subformulas() -> None:
    f = conj(until(p, nxt(q), (1, 2)), dist(DistRef("mu"), r))
    assert atoms(f) == {"p", "q", "r"}
    assert list(subformulas(p)) == [p]
    assert set(subformulas(nxt(q))) == {Next(q), q}


@pytest.mark.parametrize(
    ("f", "text"),
    [
        (conj(p, disj(q, r)), "p & (q | r)"),
        (disj(conj(p, q), r), "p & q | r"),
        (until(p, until(q, r)), "p U (q U r)"),
        (until(until(p, q), r), "(p U q) U r"),
        (until(neg(p), q, (1, 3)), "!p U[1,3] q"),
        (neg(until(p, q)), "!(p U q)"),
        (eventually(conj(p, q)), "F (p & q)"),
        (eventually(p, (0, 3)), "F[0,3] p"),
        (always(p, (2, 4)), "G[2,4] p"),
        (release(FALSE, p, (0, 2)), "false R[0,2] p"),
        (release(p, q), "p R q"),
        (nxt(neg(p)), "X !p"),
        (neg(nxt(p)), "!X p"),
        (implies(p, q), "!p | q"),
        (dist(DistRef("mu1"), p), "D[mu1] p"),
        (dist(DistLiteral("pmf", (0.1, 2, 3.0)), p), "D[pmf(0.1, 2, 3.0)] p"),
        (dist(DistLiteral("scipy", ("nbinom", 3, 0.5)), p), "D[scipy(nbinom, 3, 0.5)] p"),
        (conj(until(p, q), r), "p U q & r"),
        (until(conj(p, q), r), "(p & q) U r"),
        (Until(TRUE, TRUE, Interval(2, 3)), "F[2,3] true"),
    ],
)
def test_printing(f: Formula, text: str) -> None:
    assert str(f) == text


# --------------------------------------------------------------------------- semantics


@given(FS, FS, TRACES)
def test_boolean_simplification_preserves_meaning(
    a: Formula, b: Formula, w: tuple[frozenset[str], ...]
) -> None:
    for t in positions(w):
        va, vb = brute(a, w, t), brute(b, w, t)
        assert brute(conj(a, b), w, t) == (va and vb) == brute(And((a, b)), w, t)
        assert brute(disj(a, b), w, t) == (va or vb) == brute(Or((a, b)), w, t)
        assert brute(conj(a, TRUE), w, t) == brute(And((a, TRUE)), w, t) == va
        assert brute(disj(a, FALSE), w, t) == brute(Or((a, FALSE)), w, t) == va
        assert brute(neg(a), w, t) == (not va)
        assert brute(neg(neg(a)), w, t) == brute(Not(Not(a)), w, t) == va
        assert brute(implies(a, b), w, t) == ((not va) or vb)
        assert brute(nxt(a), w, t) == brute(a, w, t + 1) == brute(Next(a), w, t)


@given(FS, FS, st.one_of(st.none(), intervals(4)), TRACES)
def test_temporal_constructors_mean_their_definition(
    a: Formula, b: Formula, iv: Interval | None, w: tuple[frozenset[str], ...]
) -> None:
    for t in positions(w):
        assert brute(until(a, b, iv), w, t) == brute(Until(a, b, iv), w, t)
        assert brute(release(a, b, iv), w, t) == brute(Release(a, b, iv), w, t)
        # release is the dual of until
        assert brute(release(a, b, iv), w, t) == (not brute(Until(Not(a), Not(b), iv), w, t))
        assert brute(until(a, FALSE, iv), w, t) == brute(Until(a, FALSE, iv), w, t)
        assert brute(release(a, TRUE, iv), w, t) == brute(Release(a, TRUE, iv), w, t)
        if iv is not None:
            window = range(t + iv.lo, t + iv.hi + 1)
            assert brute(eventually(a, iv), w, t) == any(brute(a, w, j) for j in window)
            assert brute(always(a, iv), w, t) == all(brute(a, w, j) for j in window)
            assert brute(until(a, TRUE, iv), w, t) == brute(Until(a, TRUE, iv), w, t)
            assert brute(release(a, FALSE, iv), w, t) == brute(Release(a, FALSE, iv), w, t)
