"""Hypothesis strategies for MITLD formulas, distributions and finite traces (tests only:
importing this module needs the ``hypothesis`` package of the ``dev`` extra).

Formulas are built through the smart constructors of :mod:`mitld_lp.logic.syntax`, so
they are in the simplified form the parser produces and ``parse(str(f)) == f`` holds.
"""

from __future__ import annotations

from collections.abc import Sequence

from hypothesis import strategies as st

from mitld_lp.logic.fragment import is_co_safe
from mitld_lp.logic.syntax import (
    FALSE,
    RESERVED,
    TRUE,
    DistLiteral,
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
)

__all__ = ["KEYWORDS", "identifiers", "intervals", "dist_specs", "formulas", "traces"]

#: Words the parser reserves for operators (:data:`mitld_lp.logic.syntax.RESERVED`).
KEYWORDS = RESERVED


def identifiers() -> st.SearchStrategy[str]:
    """Names the parser reads as one identifier: ``[A-Za-z_][A-Za-z0-9_]*``, no keyword
    (including keyword-like names such as ``F1``, ``Xp``, ``true_``)."""
    return st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,5}", fullmatch=True).filter(
        lambda s: s not in KEYWORDS
    )


def intervals(max_bound: int = 6) -> st.SearchStrategy[Interval]:
    """Intervals ``[l,u]`` with ``0 <= l <= u <= max_bound`` (``l > 0`` included)."""
    return st.tuples(st.integers(0, max_bound), st.integers(0, max_bound)).map(
        lambda b: Interval(min(b), max(b))
    )


def dist_specs() -> st.SearchStrategy[DistSpec]:
    """Distribution names and valid literals of every family (values inside each
    family's domain, integers and floats mixed), so that :func:`mitld_lp.logic.parse`
    and :func:`mitld_lp.logic.check` accept them."""
    prob = st.one_of(st.floats(0.001, 1.0), st.just(1))
    positive = st.one_of(st.floats(0.01, 100.0), st.integers(1, 50))

    def lit(family: str, args: st.SearchStrategy[tuple]) -> st.SearchStrategy[DistSpec]:
        return args.map(lambda a: DistLiteral(family, tuple(a)))

    masses = st.lists(st.integers(0, 100), min_size=1, max_size=4).map(
        lambda xs: tuple(x / max(100, sum(xs)) for x in xs)
    )
    steps = st.tuples(st.integers(1, 20), st.integers(0, 20)).map(lambda t: (t[0], t[0] + t[1]))
    scipy_laws = st.sampled_from(
        [("nbinom", 3, 0.5), ("geom", 0.3), ("poisson", 2.0), ("expon",), ("gamma", 2.0)]
    )
    return st.one_of(
        identifiers().map(DistRef),
        lit("geometric", st.tuples(prob)),
        lit("pmf", masses),
        lit("poisson", st.tuples(positive)),
        lit("uniform", steps),
        lit("exponential", st.tuples(positive)),
        lit("weibull", st.tuples(positive, positive)),
        lit("gamma", st.tuples(positive, positive)),
        lit("scipy", scipy_laws),
    )


def formulas(
    props: Sequence[str] = ("p", "q", "r"),
    max_depth: int = 4,
    max_bound: int = 6,
    co_safe: bool = False,
    with_dist: bool = False,
) -> st.SearchStrategy[Formula]:
    """Formulas over ``props`` of nesting depth at most ``max_depth`` with interval bounds
    up to ``max_bound``, built by the smart constructors: constants, propositions, ``!``,
    ``&``, ``|``, ``->``, ``X``, ``F``/``G`` and ``U``/``R`` bounded (``l > 0`` included)
    and unbounded.

    ``co_safe=True``: only formulas whose NNF has no unbounded release (unbounded ``U``,
    ``F`` only under an even number of negations, unbounded ``R``, ``G`` only under an odd
    one).  ``with_dist=True``: also ``D[mu] a`` on propositions, each proposition with one
    distribution per formula and only under an even number of negations, so the result
    passes :func:`mitld_lp.logic.fragment.event_distributions`.
    """
    props = tuple(props)
    if not props:
        raise ValueError("formulas() needs at least one proposition")
    if with_dist:
        strategy = st.lists(dist_specs(), min_size=len(props), max_size=len(props)).flatmap(
            lambda mus: _Gen(props, max_bound, co_safe, dict(zip(props, mus, strict=True))).at(
                max_depth, True
            )
        )
    else:
        strategy = _Gen(props, max_bound, co_safe, None).at(max_depth, True)
    return strategy.filter(is_co_safe) if co_safe else strategy


class _Gen:
    """Draws formulas by depth and polarity (``positive``: under an even number of
    negations).  A composite draw rather than a tree of ``one_of`` strategies: the
    sub-strategies would be shared, and hypothesis prints such a tree (for notes and
    warnings) at a size exponential in the depth."""

    _OPS = ("leaf", "not", "next", "F", "G", "U", "R", "->", "&", "|")

    def __init__(
        self,
        props: tuple[str, ...],
        max_bound: int,
        co_safe: bool,
        mus: dict[str, DistSpec] | None,
    ) -> None:
        self.props = props
        self.co_safe = co_safe
        self.mus = mus
        self.iv = intervals(max_bound)

    def __repr__(self) -> str:
        return f"formulas(props={self.props!r}, co_safe={self.co_safe})"

    def at(self, depth: int, positive: bool) -> st.SearchStrategy[Formula]:
        return _draw_formula(self, depth, positive)

    def leaf(self, draw: st.DrawFn, positive: bool) -> Formula:
        kinds = ["prop", "const"] + (["dist"] if self.mus is not None and positive else [])
        kind = draw(st.sampled_from(kinds))
        if kind == "const":
            return draw(st.sampled_from((TRUE, FALSE)))
        name = draw(st.sampled_from(self.props))
        if kind == "dist" and self.mus is not None:
            return dist(self.mus[name], Prop(name))
        return Prop(name)

    def bounds(self, draw: st.DrawFn, unbounded_ok: bool) -> Interval | None:
        if (unbounded_ok or not self.co_safe) and draw(st.booleans()):
            return None
        return draw(self.iv)


@st.composite
def _draw_formula(draw: st.DrawFn, gen: _Gen, depth: int, positive: bool) -> Formula:
    op = "leaf" if depth <= 1 else draw(st.sampled_from(_Gen._OPS))
    if op == "leaf":
        return gen.leaf(draw, positive)

    def sub(pos: bool = positive) -> Formula:
        return draw(_draw_formula(gen, depth - 1, pos))

    match op:
        case "not":
            return neg(sub(not positive))
        case "next":
            return nxt(sub())
        case "F":
            return eventually(sub(), gen.bounds(draw, positive))
        case "G":
            return always(sub(), gen.bounds(draw, not positive))
        case "U":
            return until(sub(), sub(), gen.bounds(draw, positive))
        case "R":
            return release(sub(), sub(), gen.bounds(draw, not positive))
        case "->":
            return implies(sub(not positive), sub())
        case _:
            operands = [sub() for _ in range(draw(st.integers(2, 3)))]
            return conj(*operands) if op == "&" else disj(*operands)


def traces(
    props: Sequence[str] = ("p", "q", "r"), min_len: int = 0, max_len: int = 20
) -> st.SearchStrategy[tuple[frozenset[str], ...]]:
    """Finite traces: tuples of letters, each the frozenset of propositions true at that
    step."""
    letter = st.frozensets(st.sampled_from(tuple(props)))
    return st.lists(letter, min_size=min_len, max_size=max_len).map(tuple)
