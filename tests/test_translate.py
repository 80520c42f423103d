"""Independent checks of the MITL -> DTA translation (``mitld_lp.automata.translate``).

Expected values come from three routes that do not share code with the translation:

* the reference Kleene semantics :func:`mitld_lp.logic.semantics.holds` (the DTA must
  accept a finite trace exactly when the verdict is TRUE);
* the independent ``metric-temporal-logic`` package (``import mtl``, version 0.4.x) with
  ``dt = 1``, on traces long enough to decide a bounded formula;
* hand counts (sizes of the automata of ``F[0,k] p`` and ``G[0,k] p``) and a brute-force
  Myhill-Nerode count of the residual languages written with ``holds`` only.

Semantic differences between ``mtl`` (0.4.1) and our semantics, found by experiment (each
one is pinned by a ``test_mtl_difference_*`` test below so that a change of ``mtl`` is
noticed):

1. **Intervals are half-open at dt = 1.**  ``mtl`` reads a sampled signal as piecewise
   constant, and its window ``[a, b]`` covers the samples ``t+a .. t+b-1``: ``F[0,2] p``
   is false on ``{}, {}, {p}``.  So our ``F[l,u]`` / ``G[l,u]`` is ``mtl``'s
   ``F[l,u+1]`` / ``G[l,u+1]``.
2. **Degenerate windows are wrong in mtl.**  ``G[a,a] phi`` evaluates ``phi`` at ``t``
   (not at ``t+a``), so ``F[2,2] p`` is false when ``p`` holds only at step 2.  (With the
   shift of item 1 we never produce one.)
3. **Timed until differs.**  ``mtl`` defines ``phi U[l,u] psi`` as
   ``F[l,u] psi & G[0,l] phi & G[l,l](phi U psi)``.  By item 2 the last conjunct is the
   untimed until at ``t`` and ``G[0,0] phi`` is ``phi`` at ``t``: so ``p U[0,2] q`` is
   *false* in ``mtl`` on ``{q}, {}, {}`` (we need no ``p`` when ``q`` holds at once), and
   the witnesses of the two conjuncts need not coincide: ``p U[1,2] q`` is *true* in
   ``mtl`` on ``{p,q}, {}, {q}`` (``p U q`` by ``q`` at 0, ``F`` by ``q`` at 2) but false
   for us (``p`` fails at step 1 before the only witness in the window).  Untimed
   ``U`` agrees (``psi`` at some ``j``, ``phi`` on ``[t, j)``, ``psi`` at ``t`` is enough).
4. **End of the signal.**  ``mtl`` holds the last sample forever; our semantics makes
   every letter after the trace unknown.  On a bounded formula with a trace longer than
   its horizon the two agree; with unbounded ``F``/``U`` only ``accepted ->`` ``mtl`` true
   and ``holds`` FALSE ``->`` ``mtl`` false can be compared.

So the comparison with ``mtl`` is restricted to ``!``, ``&``, ``|``, ``X`` and bounded
``F``/``G`` (exact equality) plus untimed ``U`` and unbounded ``F`` in positive position
(the two implications of item 4).
"""

from __future__ import annotations

import itertools
import re
from collections import deque

import mtl
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from mtl import sugar

from mitld_lp.automata.translate import progress, to_dta
from mitld_lp.logic import parse
from mitld_lp.logic import syntax as S
from mitld_lp.logic.semantics import Verdict, holds
from mitld_lp.testing.hypothesis import formulas, traces

PROPS = ("p", "q", "r")


def examples(n: int) -> settings:
    return settings(max_examples=n, deadline=None, suppress_health_check=list(HealthCheck))


def letters_over(atoms) -> list[frozenset[str]]:
    atoms = sorted(atoms)
    return [frozenset(c) for r in range(len(atoms) + 1) for c in itertools.combinations(atoms, r)]


def final_state(dta, trace) -> int:
    s = dta.initial
    for letter in trace:
        s = dta.step(s, letter)
    return s


# --------------------------------------------------------------------------- reference semantics


def waits_on_true(f: S.Formula) -> bool:
    """Whether the NNF of ``f`` has ``true U[l,u] true`` with ``l > 0`` (``F[l,u] true``):
    the translation did not fold it to ``true`` at first (regression test below)."""
    return any(
        isinstance(g, S.Until)
        and g.left == S.TRUE
        and g.right == S.TRUE
        and g.interval is not None
        and g.interval.lo > 0
        for g in S.subformulas(to_dta(f).formula)
    )


@examples(400)
@given(formulas(PROPS, max_depth=5, max_bound=6, co_safe=True), traces(PROPS, 0, 15))
def test_dta_accepts_exactly_the_kleene_true_prefixes(phi, trace):
    assume(not waits_on_true(phi))
    dta = to_dta(phi)
    verdict = holds(phi, trace)
    assert dta.run(trace) == (verdict is Verdict.TRUE)
    # Acceptance is reaching the absorbing accepting state: every prefix agrees too.
    s = dta.initial
    for i, letter in enumerate(trace):
        s = dta.step(s, letter)
        assert dta.is_accepting(s) == (holds(phi, trace[: i + 1]) is Verdict.TRUE)
    # A FALSE verdict is final: no extension can be accepted, so the run sits in the
    # dead (rejecting) state.
    if verdict is Verdict.FALSE:
        assert dta.rejecting is not None and final_state(dta, trace) == dta.rejecting


@examples(200)
@given(formulas(PROPS, max_depth=4, max_bound=6, co_safe=True), traces(PROPS, 0, 12))
def test_progress_letter_by_letter_matches_the_reference(phi, trace):
    """Folding ``progress`` over the trace from the NNF obligation reaches ``true``
    exactly on the Kleene-TRUE prefixes (``true`` is absorbing)."""
    assume(not waits_on_true(phi))
    ob = to_dta(phi).formula
    for i, letter in enumerate(trace):
        ob = progress(ob, letter)
        assert (ob == S.TRUE) == (holds(phi, trace[: i + 1]) is Verdict.TRUE)
        if ob == S.FALSE:
            assert holds(phi, trace[: i + 1]) is not Verdict.TRUE


@pytest.mark.parametrize("text", ["F[1,1] true", "F[2,3] true", "p | F[2,2] true"])
def test_eventually_true_with_lower_bound_is_true(text):
    phi = parse(text)
    assert holds(phi, []) is Verdict.TRUE
    d = to_dta(phi)
    assert d.run([]) and d.run([frozenset()])
    assert d.n_states == 1


def test_lower_bounds_and_nesting_by_hand():
    # F[2,4] p: p must hold at one of the steps 2, 3, 4.
    d = to_dta(parse("F[2,4] p"))
    e, p = frozenset(), frozenset({"p"})
    assert not d.run([p, p])
    assert d.run([p, e, p])
    assert d.run([e, e, e, e, p])
    assert not d.run([e, e, e, e, e, p])
    # p U[2,3] q: q at step 2 or 3, p at every step before the witness.
    d = to_dta(parse("p U[2,3] q"))
    pq, q = frozenset({"p", "q"}), frozenset({"q"})
    assert d.run([p, p, q])
    assert not d.run([p, e, q])
    assert not d.run([q, q])  # a witness before step 2 does not count
    assert d.run([pq, p, p, q])
    # G[1,2] p is vacuous at step 0.
    d = to_dta(parse("G[1,2] p"))
    assert d.run([e, p, p]) and not d.run([p, e, p])
    # p R[1,2] q: q at 1 and 2 unless p released it strictly before.
    d = to_dta(parse("p R[1,2] q"))
    assert d.run([p, e, e])  # p at 0 releases both obligations
    assert d.run([e, pq])  # q at 1, p at 1 releases step 2
    assert not d.run([e, p])
    # nesting: F[0,2] G[0,1] p needs two consecutive p starting by step 2
    d = to_dta(parse("F[0,2] G[0,1] p"))
    assert d.run([e, e, p, p]) and not d.run([p, e, p, e, p])


# --------------------------------------------------------------------------- against mtl


def _tree(depth: int, positive: bool, unbounded: bool):
    leaf = st.sampled_from(PROPS).map(lambda a: ("ap", a))
    if depth <= 1:
        return leaf
    same = st.deferred(lambda: _tree(depth - 1, positive, unbounded))
    flip = st.deferred(lambda: _tree(depth - 1, not positive, unbounded))
    bounds = st.tuples(st.integers(0, 4), st.integers(0, 3)).map(lambda b: (b[0], b[0] + b[1]))
    options = [
        leaf,
        flip.map(lambda a: ("not", a)),
        st.tuples(same, same).map(lambda ab: ("and", *ab)),
        st.tuples(same, same).map(lambda ab: ("or", *ab)),
        same.map(lambda a: ("X", a)),
        st.tuples(bounds, same).map(lambda b: ("F", b[0][0], b[0][1], b[1])),
        st.tuples(bounds, same).map(lambda b: ("G", b[0][0], b[0][1], b[1])),
    ]
    if unbounded and positive:
        options.append(st.tuples(same, same).map(lambda ab: ("U", *ab)))
        options.append(same.map(lambda a: ("Fu", a)))
    return st.one_of(*options)


def ours(t) -> S.Formula:
    match t:
        case ("ap", a):
            return S.Prop(a)
        case ("not", a):
            return S.neg(ours(a))
        case ("and", a, b):
            return S.conj(ours(a), ours(b))
        case ("or", a, b):
            return S.disj(ours(a), ours(b))
        case ("X", a):
            return S.nxt(ours(a))
        case ("F", lo, hi, a):
            return S.eventually(ours(a), (lo, hi))
        case ("G", lo, hi, a):
            return S.always(ours(a), (lo, hi))
        case ("U", a, b):
            return S.until(ours(a), ours(b))
        case ("Fu", a):
            return S.eventually(ours(a))
        case ("Gu", a):
            return S.always(ours(a))
    raise AssertionError(t)


def theirs(t):
    """The same formula in mtl, with our closed [l,u] as mtl's [l,u+1] (difference 1)."""
    match t:
        case ("ap", a):
            return mtl.ast.AtomicPred(a)
        case ("not", a):
            return ~theirs(a)
        case ("and", a, b):
            return theirs(a) & theirs(b)
        case ("or", a, b):
            return theirs(a) | theirs(b)
        case ("X", a):
            return mtl.ast.Next(theirs(a))
        case ("F", lo, hi, a):
            return sugar.env(theirs(a), lo=lo, hi=hi + 1)
        case ("G", lo, hi, a):
            return sugar.alw(theirs(a), lo=lo, hi=hi + 1)
        case ("U", a, b):
            return theirs(a).until(theirs(b))
        case ("Fu", a):
            return sugar.env(theirs(a))
        case ("Gu", a):
            return sugar.alw(theirs(a))
    raise AssertionError(t)


def horizon(t) -> int:
    match t:
        case ("ap", _):
            return 0
        case ("not", a):
            return horizon(a)
        case ("X", a):
            return 1 + horizon(a)
        case ("and", a, b) | ("or", a, b) | ("U", a, b):
            return max(horizon(a), horizon(b))
        case ("F", _, hi, a) | ("G", _, hi, a):
            return hi + horizon(a)
        case ("Fu", a):
            return horizon(a)
    raise AssertionError(t)


def signal(trace):
    return {a: [(i, a in letter) for i, letter in enumerate(trace)] for a in PROPS}


def mtl_holds(t, trace) -> bool:
    return bool(theirs(t)(signal(trace), time=0, dt=1, quantitative=False))


@st.composite
def bounded_case(draw):
    t = draw(_tree(5, True, unbounded=False))
    n = horizon(t) + 1 + draw(st.integers(0, 3))
    trace = draw(traces(PROPS, n, n))
    return t, trace


@examples(300)
@given(bounded_case())
def test_dta_agrees_with_mtl_on_decided_bounded_formulas(case):
    t, trace = case
    phi = ours(t)
    assert holds(phi, trace) is not Verdict.UNKNOWN  # the trace decides the formula
    assert to_dta(phi).run(trace) == mtl_holds(t, trace)


@examples(150)
@given(_tree(4, True, unbounded=True), traces(PROPS, 1, 10))
def test_dta_verdicts_imply_mtl_with_unbounded_operators(t, trace):
    """mtl extends the last letter forever (difference 4): a good prefix must be true
    there, and a prefix the reference calls FALSE must be false there."""
    phi = ours(t)
    if to_dta(phi).run(trace):
        assert mtl_holds(t, trace)
    if holds(phi, trace) is Verdict.FALSE:
        assert not mtl_holds(t, trace)


def _e(*names: str) -> frozenset[str]:
    return frozenset(names)


def test_mtl_difference_half_open_windows():
    trace = [_e(), _e(), _e("p"), _e()]
    assert to_dta(parse("F[0,2] p")).run(trace)
    assert not mtl.parse("F[0,2] p")(signal(trace), time=0, dt=1, quantitative=False)
    assert mtl.parse("F[0,3] p")(signal(trace), time=0, dt=1, quantitative=False)


def test_mtl_difference_degenerate_window():
    trace = [_e(), _e(), _e("p"), _e()]
    assert to_dta(parse("F[2,2] p")).run(trace)
    assert not mtl.parse("F[2,2] p")(signal(trace), time=0, dt=1, quantitative=False)
    assert mtl.parse("F[2,3] p")(signal(trace), time=0, dt=1, quantitative=False)


def test_mtl_difference_timed_until():
    sig = signal([_e("q"), _e(), _e(), _e()])
    assert to_dta(parse("p U[0,2] q")).run([_e("q"), _e(), _e(), _e()])
    assert not mtl.parse("(p U[0,3] q)")(sig, time=0, dt=1, quantitative=False)
    trace = [_e("p", "q"), _e(), _e("q"), _e()]
    assert not to_dta(parse("p U[1,2] q")).run(trace)
    assert mtl.parse("(p U[1,3] q)")(signal(trace), time=0, dt=1, quantitative=False)


def test_mtl_difference_end_of_signal():
    trace = [_e(), _e("p")]
    assert not to_dta(parse("F[3,5] p")).run(trace)  # steps 3..5 are unknown
    assert holds(parse("F[3,5] p"), trace) is Verdict.UNKNOWN
    assert mtl.parse("F[3,6] p")(signal(trace), time=0, dt=1, quantitative=False)


# --------------------------------------------------------------------------- minimality

EQUIVALENT = [
    ("F[0,3] p | F[0,2] p", "F[0,3] p"),
    ("F[0,2] F[0,3] p", "F[0,5] p"),
    ("p & q", "q & p"),
    ("!(!p | !q)", "p & q"),
    ("G[0,2] p", "p & X p & X X p"),
    ("F[1,3] p", "X F[0,2] p"),
    ("p U[0,3] q | q", "p U[0,3] q"),
    ("F[0,2] p | F[3,5] p", "F[0,5] p"),
    ("G[0,3] (p & q)", "G[0,3] p & G[0,3] q"),
    ("!G[0,3] !p", "F[0,3] p"),
    ("true U[0,4] p", "F[0,4] p"),
    ("X (p | q)", "X p | X q"),
    ("F[0,2] (p | q)", "F[0,2] p | F[0,2] q"),
    ("G[1,3] p", "X G[0,2] p"),
    ("p R[0,2] q", "!(!p U[0,2] !q)"),
    ("F[0,1] p & F[0,3] p", "F[0,1] p"),
    ("F[2,3] p | F[0,1] p", "F[0,3] p"),
]


def _agree_up_to(d1, d2, letters, depth: int) -> None:
    """Every trace of length <= depth over ``letters`` is accepted by both or neither
    (exhaustive: memoised on the pair of states and the length left)."""
    seen: set[tuple[int, int, int]] = set()
    stack = [(d1.initial, d2.initial, depth, ())]
    while stack:
        s1, s2, left, word = stack.pop()
        assert d1.is_accepting(s1) == d2.is_accepting(s2), word
        if left == 0 or (s1, s2, left) in seen:
            continue
        seen.add((s1, s2, left))
        for letter in letters:
            stack.append((d1.step(s1, letter), d2.step(s2, letter), left - 1, (*word, letter)))


@pytest.mark.parametrize(("left", "right"), EQUIVALENT)
def test_equivalent_formulas_get_equal_minimal_dtas(left, right):
    f, g = parse(left), parse(right)
    d1, d2 = to_dta(f), to_dta(g)
    letters = letters_over(S.atoms(f) | S.atoms(g))
    assert d1.n_states == d2.n_states
    _agree_up_to(d1, d2, letters, 6)
    # And the accepted traces are the reference's (spot-check every trace of length 4).
    for trace in itertools.product(letters, repeat=4):
        assert d1.run(trace) == (holds(f, trace) is Verdict.TRUE)


@pytest.mark.parametrize("k", range(31))
def test_size_of_bounded_eventually(k):
    # F[0,k] p: the obligations F[0,k] p (initial), F[0,k-1] p, ..., F[0,0] p (k + 1
    # states: the initial one and k waiting ones), then reading p anywhere goes to
    # `true` (accept) and reading !p in F[0,0] p goes to `false` (reject): k + 3.
    d = to_dta(parse(f"F[0,{k}] p"))
    assert d.n_states == k + 3
    assert d.accepting is not None and d.rejecting is not None
    p, e = frozenset({"p"}), frozenset()
    assert d.run([e] * k + [p]) and not d.run([e] * (k + 1) + [p])


@pytest.mark.parametrize("k", range(31))
def test_size_of_bounded_always(k):
    # G[0,k] p: obligations G[0,k] p, ..., G[0,0] p (k + 1), plus `true` after k + 1
    # letters with p, plus `false` on the first !p: k + 3.
    d = to_dta(parse(f"G[0,{k}] p"))
    assert d.n_states == k + 3
    p, e = frozenset({"p"}), frozenset()
    assert d.run([p] * (k + 1)) and not d.run([p] * k)
    assert not d.run([p] * k + [e] + [p] * 5)


def _myhill_nerode_classes(phi, atoms, horizon_: int) -> int:
    """The number of residual languages of the Kleene-TRUE prefixes of a bounded
    formula, from ``holds`` only.  Prefixes up to length horizon+1 reach every residual
    (after that the verdict is fixed); suffixes up to length horizon+1 tell them apart
    (a residual only reads positions <= horizon).  A residual is tabulated on all
    suffixes of length <= horizon+1, its value on a suffix longer than needed read off
    the prefix of that suffix which reaches position horizon."""
    letters = letters_over(atoms)
    n = horizon_ + 1
    suffixes = [v for m in range(n + 1) for v in itertools.product(letters, repeat=m)]
    classes = set()
    for k in range(n + 1):
        for w in itertools.product(letters, repeat=k):
            memo: dict[tuple, bool] = {}
            sig = []
            for v in suffixes:
                v = v[: max(0, n - k)]
                if v not in memo:
                    memo[v] = holds(phi, w + v) is Verdict.TRUE
                sig.append(memo[v])
            classes.add(tuple(sig))
    return len(classes)


@pytest.mark.parametrize(
    ("text", "horizon_"),
    [
        ("F[0,2] p", 2),
        ("F[1,3] p", 3),
        ("G[1,2] p", 2),
        ("p U[1,2] q", 2),
        ("p R[0,2] q", 2),
        ("F[0,1] (p & X q)", 2),
        ("G[0,1] F[0,1] p", 2),
        ("X p | F[0,2] q", 2),
        ("(p & F[1,2] q) | G[0,2] !q", 2),
        ("F[0,2] p & F[0,2] q", 2),
    ],
)
def test_size_is_the_myhill_nerode_count(text, horizon_):
    phi = parse(text)
    assert to_dta(phi).n_states == _myhill_nerode_classes(phi, S.atoms(phi), horizon_)


# --------------------------------------------------------------------------- the paper's example

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"


@pytest.fixture(scope="module")
def paper_dta():
    return to_dta(parse(PAPER))


@pytest.mark.parametrize(
    ("trace", "accepted"),
    [
        ([[], ["b1"], [], ["A"]], True),  # the paper's run (b3 = A)
        ([[], ["b1"], [], [], [], ["A"]], False),  # A 4 steps after b1: too late
        ([[], ["b1"], [], [], ["A"]], True),  # exactly 3 steps after
        ([["b1", "A"]], True),  # same step
        ([["A"], ["b1"]], False),  # A before b1 is no witness
        ([["A"], ["b1"], [], [], [], []], False),
        ([["b2"], [], [], ["B"]], True),
        ([["b2"], [], [], [], ["B"]], False),
        ([["b1", "b2"], [], ["B"]], True),
        ([["B"], ["A"], ["b1"], ["b2"]], False),
        ([["b1"], [], [], [], ["b2"], ["A"], [], ["B"]], True),  # second bus in time
        ([[], [], [], []], False),
    ],
)
def test_paper_example_runs(paper_dta, trace, accepted):
    trace = [frozenset(x) for x in trace]
    assert paper_dta.run(trace) == accepted
    assert (holds(parse(PAPER), trace) is Verdict.TRUE) == accepted


def test_paper_example_transition_function_is_total(paper_dta):
    d = paper_dta
    assert set(d.atoms) == {"A", "B", "b1", "b2"}
    letters = letters_over(d.atoms)
    assert len(letters) == 16
    for s in range(d.n_states):
        for letter in letters:
            t = d.step(s, letter)
            assert 0 <= t < d.n_states
            # letters outside the atoms are ignored
            assert d.step(s, letter | {"zzz"}) == t
    assert d.accepting is not None
    assert all(d.step(d.accepting, letter) == d.accepting for letter in letters)
    # every state is reachable from the initial one
    seen, queue = {d.initial}, deque([d.initial])
    while queue:
        s = queue.popleft()
        for letter in letters:
            t = d.step(s, letter)
            if t not in seen:
                seen.add(t)
                queue.append(t)
    assert seen == set(range(d.n_states))


def test_paper_example_dot_is_valid(paper_dta):
    dot = paper_dta.to_dot()
    assert dot.lstrip().startswith("digraph")
    body = re.sub(r'"(?:[^"\\]|\\.)*"', '""', dot)  # drop quoted labels
    assert body.count("{") == body.count("}") == 1
    nodes = re.findall(r"^\s*(s\d+)\s*\[", dot, flags=re.M)
    assert sorted(nodes) == sorted(f"s{i}" for i in range(paper_dta.n_states))
    assert len(set(nodes)) == len(nodes)
    edges = re.findall(r"^\s*(\w+)\s*->\s*(\w+)", dot, flags=re.M)
    known = set(nodes) | {"__init"}
    assert edges and all(a in known and b in known for a, b in edges)
    assert ("__init", f"s{paper_dta.initial}") in edges
    # one edge per (state, successor) pair
    assert len(edges) == len(set(edges))
    for s in range(paper_dta.n_states):
        out = {b for a, b in edges if a == f"s{s}"}
        assert out == {f"s{t}" for t in paper_dta.successors(s)}


def _location_shape(text: str) -> str:
    # the clock values removed by hand, independently of Location.obligation
    return re.sub(r" \{x=\d+\}", "", text)


def test_paper_example_locations_and_clocks(paper_dta):
    """Fig. 1 of the paper has 5 locations (l0, l1, l2, l4 and the accepting l3; the
    sink is omitted) and 4 clocks (x1, x2 for the two D operators, x3, x4 for the two
    F<=3).  Here the event clocks live in the STA (one shared clock, none at all for a
    geometric event), so the DTA has 2 clocks, one per F[0,3]; with the disjuncts of a
    location put in a canonical order there are the same 5 locations: l0 (waiting for a
    bus), l1 (F[0,3] A running), l2 (F[0,3] B running), l4 (both running), accepting.
    Unlike Fig. 1, a missed deadline goes back to l0 (or l1/l2), not to a sink: the DTA
    does not know that an event happens once (the product's pending set does), so it has
    no rejecting state at all.  17 states = 1 + 3 + 3 + 9 clock valuations + accept."""
    d = paper_dta
    assert d.rejecting is None
    clocks = {name for s in range(d.n_states) for name, _ in d.clocks(s)}
    assert clocks == {"F[0,3] A", "F[0,3] B"}
    for s in range(d.n_states):
        assert all(1 <= v <= 3 for _, v in d.clocks(s))

    def canonical(s: int) -> str:
        return " | ".join(sorted(_location_shape(d.location(s).label).split(" | ")))

    locations = {canonical(s) for s in range(d.n_states)}
    assert len(locations) == 5
    by_clocks = {}
    for s in range(d.n_states):
        by_clocks.setdefault(frozenset(n for n, _ in d.clocks(s)), []).append(s)
    # l0 and accept carry no clock; l1, l2 three valuations each; l4 nine.
    assert sorted(len(v) for v in by_clocks.values()) == [2, 3, 3, 9]
    assert d.n_states == 17


def test_paper_example_location_text_is_canonical(paper_dta):
    d = paper_dta
    assert len({_location_shape(d.location(s).label) for s in range(d.n_states)}) == 5
