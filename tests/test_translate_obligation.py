"""The automaton of safety and obligation formulas: state kinds and infinite runs.

Expected verdicts come from routes that do not share code with the translation:

* the reference semantics on infinite ultimately periodic words,
  :func:`mitld_lp.logic.semantics.holds_lasso` (itself checked against the quantifiers of
  the definitions in ``tests/test_semantics.py``): the automaton accepts ``u v v ...``
  (its run reaches ``true`` or ends on a cycle of safe states) exactly when the formula
  holds there;
* the Kleene reading of finite prefixes, :func:`mitld_lp.logic.semantics.holds`: a
  prefix it decides false ends in the rejecting state;
* the independent ``metric-temporal-logic`` package (``import mtl``), which holds the last
  letter of a finite signal for ever: the lasso whose loop is that one letter (with the
  interval shift documented in ``tests/test_translate.py``);
* hand counts of states and kinds.
"""

from __future__ import annotations

import itertools
from collections import deque

import mtl
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from test_translate import ours, theirs  # the same trees in our syntax and in mtl's

from mitld_lp.automata.dta import ACCEPT, OPEN, REJECT, SAFE
from mitld_lp.automata.translate import to_dta
from mitld_lp.logic import parse
from mitld_lp.logic import syntax as S
from mitld_lp.logic.fragment import (
    CO_SAFE,
    OBLIGATION,
    SAFETY,
    SUPPORTED,
    classify,
)
from mitld_lp.logic.semantics import Verdict, holds, holds_lasso
from mitld_lp.testing.hypothesis import formulas, traces

PROPS = ("p", "q", "r")
LETTERS = [frozenset(c) for n in range(len(PROPS) + 1) for c in itertools.combinations(PROPS, n)]


def examples(n: int) -> settings:
    return settings(max_examples=n, deadline=None, suppress_health_check=list(HealthCheck))


def co_safe(depth: int = 3) -> st.SearchStrategy[S.Formula]:
    return formulas(PROPS, max_depth=depth, max_bound=3, co_safe=True)


def safety(depth: int = 3) -> st.SearchStrategy[S.Formula]:
    """The negation of a co-safe formula is a safety formula."""
    return co_safe(depth).map(S.neg)


@st.composite
def obligations(draw: st.DrawFn) -> S.Formula:
    """``&``/``|`` combinations of co-safe and safety formulas, possibly under ``X`` or a
    bounded ``F``/``G`` (which keep the class)."""
    parts = draw(st.lists(st.one_of(co_safe(), safety()), min_size=1, max_size=3))
    f = parts[0]
    for g in parts[1:]:
        f = S.conj(f, g) if draw(st.booleans()) else S.disj(f, g)
    wrap = draw(st.sampled_from(["none", "X", "F", "G"]))
    if wrap == "X":
        f = S.nxt(f)
    elif wrap in ("F", "G"):
        lo = draw(st.integers(0, 2))
        hi = lo + draw(st.integers(0, 2))
        f = (S.eventually if wrap == "F" else S.always)(f, (lo, hi))
    return f


def kinds(text: str) -> list[tuple[str, str]]:
    d = to_dta(parse(text))
    return sorted((str(d.states[i]), d.kind(i)) for i in range(d.n_states))


# --------------------------------------------------------------------------- by hand


def test_safety_kinds_by_hand() -> None:
    assert kinds("G !h") == [("false", REJECT), ("false R !h", SAFE)]
    # the window after a p is 3, 2, 1 or 0 steps long: four safe states and the rejection
    d = to_dta(parse("G (p -> F[0,3] q)"))
    assert d.fragment == SAFETY
    assert sorted(d.kinds) == [REJECT] + [SAFE] * 4
    # !h W goal: h before goal is a violation, goal ends the task
    assert kinds("!h W goal") == [("!h W goal", SAFE), ("false", REJECT), ("true", ACCEPT)]
    # X G p: the first step is open (passed once), then G p
    d = to_dta(parse("X G p"))
    assert d.kind(d.initial) == OPEN and d.kind(d.step(d.initial, set())) == SAFE


def test_obligation_kinds_by_hand() -> None:
    # G p | F q: keeping p for ever is enough while q has not come
    d = to_dta(parse("G p | F q"))
    assert d.fragment == OBLIGATION
    assert d.kind(d.initial) == SAFE
    assert d.kind(d.step(d.initial, {"q"})) == ACCEPT
    assert d.kind(d.step(d.initial, set())) == OPEN  # F q alone
    # G !h & F goal: safe only once goal has come
    d = to_dta(parse("G !h & F goal"))
    assert d.kind(d.initial) == OPEN
    assert d.kind(d.step(d.initial, {"goal"})) == SAFE
    assert d.kind(d.step(d.initial, {"h"})) == REJECT
    assert d.accepts_lasso([set(), {"goal"}], [set()])
    assert not d.accepts_lasso([], [set()])  # goal never comes
    assert not d.accepts_lasso([{"goal"}], [set(), {"h"}])  # h after goal


def test_the_bus_task_with_a_hazard() -> None:
    """The issue's task: never the hazard, and be at the stop within 3 steps of the bus."""
    d = to_dta(parse("G !hazard & (D[mu] bus & F(bus & F[0,3] stop))"))
    assert d.fragment == OBLIGATION
    # the bus at step 1, the stop at step 3 (two steps later), never the hazard
    assert d.accepts_lasso([set(), {"bus"}, set(), {"stop"}], [set()])
    # the stop at step 5 is too late; the hazard at step 6 after an on-time stop is fatal
    assert not d.accepts_lasso([set(), {"bus"}, set(), set(), set(), {"stop"}], [set()])
    assert not d.accepts_lasso([{"bus"}, {"stop"}, set(), set()], [set(), {"hazard"}])
    # the same states as F(bus & F[0,3] stop) (waiting, three windows, done) and false
    assert d.n_states == 6


def test_co_safe_formulas_have_no_safe_state() -> None:
    for text in ("F p", "p U q", "F[0,3] p", "(D[mu] b & F(b & F[0,3] A)) | F[2,4] B"):
        d = to_dta(parse(text))
        assert d.fragment == CO_SAFE
        assert SAFE not in d.kinds
        assert d.persistent == ({d.accepting} if d.accepting is not None else set())


def test_equal_languages_different_kinds_are_not_merged() -> None:
    """G p and false accept no finite prefix; on infinite runs they differ."""
    d = to_dta(parse("(q & G p) | (!q & F[0,0] false)"))
    s_g = d.step(d.initial, {"q", "p"})
    s_f = d.step(d.initial, set())
    assert d.kind(s_g) == SAFE and d.kind(s_f) == REJECT and s_g != s_f


# --------------------------------------------------------------------------- semantics


@examples(300)
@given(obligations(), traces(PROPS, 0, 6), traces(PROPS, 1, 4))
def test_lasso_acceptance_is_the_semantics(phi, prefix, loop) -> None:
    d = to_dta(phi)
    assert d.fragment in SUPPORTED
    assert d.accepts_lasso(prefix, loop) == holds_lasso(phi, prefix, loop)


@examples(150)
@given(formulas(PROPS, max_depth=4, max_bound=3).filter(lambda f: classify(f) in SUPPORTED),
       traces(PROPS, 0, 6), traces(PROPS, 1, 4))
def test_lasso_acceptance_on_formulas_of_any_shape(phi, prefix, loop) -> None:
    assert to_dta(phi).accepts_lasso(prefix, loop) == holds_lasso(phi, prefix, loop)


def _short_cycles(d, s: int, length: int):
    """Every word of ``length`` letters that leads from ``s`` back to ``s``."""
    for word in itertools.product(LETTERS, repeat=length):
        t = s
        for letter in word:
            t = d.step(t, letter)
        if t == s:
            yield list(word)


@examples(40)
@given(obligations())
def test_every_short_cycle_of_a_state_has_its_kind(phi) -> None:
    """A component's kind is read off one cycle; every cycle of length 1 or 2 through
    every state must give the same verdict (the automaton is weak)."""
    d = to_dta(phi)
    for s in range(d.n_states):
        for length in (1, 2):
            for word in _short_cycles(d, s, length):
                assert holds_lasso(d.states[s], [], word) == (s in d.persistent), (
                    str(phi), str(d.states[s]), word)


def _accepted_extension(d, s: int):
    """A lasso from ``s`` that the automaton accepts (a path to a persistent state and a
    cycle of at most three letters through it inside the persistent set), or None when
    no reachable persistent state has one."""
    keep = d.persistent
    back: dict[int, tuple[int, frozenset[str]] | None] = {s: None}
    queue = deque([s])
    while queue:
        v = queue.popleft()
        if v in keep:
            path: list[frozenset[str]] = []
            x = v
            while back[x] is not None:
                x, letter = back[x]  # type: ignore[misc]
                path.append(letter)
            path.reverse()
            for length in (1, 2, 3):
                for word in _short_cycles(d, v, length):
                    t, inside = v, True
                    for letter in word:
                        inside = inside and t in keep
                        t = d.step(t, letter)
                    if inside:
                        return path, word
            # no short cycle through v itself: one may run through a persistent state
            # further on (v -> w -> w ...), so v's successors are searched too
        for letter in LETTERS:
            w = d.step(v, letter)
            if w not in back:
                back[w] = (v, letter)
                queue.append(w)
    return None


@examples(200)
@given(safety(4), traces(PROPS, 0, 8), traces(PROPS, 1, 3))
# CI found it: the only short accepted cycle runs through a persistent state past the
# first one reached (5 -{}-> 1 -{}-> 1), which the search used to stop at
@example(phi=S.Not(S.Until(S.TRUE, S.Next(S.Release(S.Prop("q"), S.Prop("p"),
                                                    S.Interval(0, 3))), None)),
         trace=(frozenset(), frozenset({"p"}), frozenset({"p"}), frozenset({"p"})),
         loop=(frozenset(),))
def test_a_safety_prefix_is_bad_exactly_when_the_run_is_rejected(phi, trace, loop) -> None:
    """Reaching the rejecting state means no extension satisfies the formula; any other
    state has an extension that does (checked by the semantics, not the automaton); and a
    prefix the Kleene reading decides false is rejected."""
    d = to_dta(phi)
    s = d.initial
    for letter in trace:
        s = d.step(s, letter)
    if holds(phi, trace) is Verdict.FALSE:
        assert d.is_rejecting(s)
    if d.is_rejecting(s):
        assert not holds_lasso(phi, trace, loop)
    else:
        found = _accepted_extension(d, s)
        assert found is not None
        path, word = found
        assert holds_lasso(phi, list(trace) + path, word)


# --------------------------------------------------------------------------- against mtl


def _tree(depth: int):
    """Formulas as trees for both libraries: ! & | X, bounded F and G, unbounded F, G and
    untimed U (mtl's timed until differs from ours, see tests/test_translate.py)."""
    leaf = st.sampled_from(PROPS).map(lambda a: ("ap", a))
    if depth <= 1:
        return leaf
    sub = st.deferred(lambda: _tree(depth - 1))
    bounds = st.tuples(st.integers(0, 3), st.integers(0, 3)).map(lambda b: (b[0], b[0] + b[1]))
    return st.one_of(
        leaf,
        sub.map(lambda a: ("not", a)),
        st.tuples(sub, sub).map(lambda ab: ("and", *ab)),
        st.tuples(sub, sub).map(lambda ab: ("or", *ab)),
        sub.map(lambda a: ("X", a)),
        st.tuples(bounds, sub).map(lambda b: ("F", *b[0], b[1])),
        st.tuples(bounds, sub).map(lambda b: ("G", *b[0], b[1])),
        sub.map(lambda a: ("Fu", a)),
        sub.map(lambda a: ("Gu", a)),
        st.tuples(sub, sub).map(lambda ab: ("U", *ab)),
    )


@examples(300)
@given(_tree(4).filter(lambda t: classify(ours(t)) in SUPPORTED), traces(PROPS, 1, 8))
def test_agrees_with_mtl_when_the_last_letter_repeats(t, trace) -> None:
    signal = {a: [(i, a in letter) for i, letter in enumerate(trace)] for a in PROPS}
    expected = bool(theirs(t)(signal, time=0, dt=1, quantitative=False))
    assert to_dta(ours(t)).accepts_lasso(trace[:-1], trace[-1:]) == expected


@pytest.mark.parametrize(
    ("text", "their_text", "trace", "truth"),
    [
        ("G !p", "G(~p)", [set(), set()], True),
        ("G !p", "G(~p)", [set(), {"p"}], False),
        ("G (p -> F[0,1] q)", "G(p -> F[0,2](q))", [{"p"}, {"q"}, set()], True),
        ("G (p -> F[0,1] q)", "G(p -> F[0,2](q))", [{"p"}, set(), set()], False),
        ("G p | F q", "(G(p) | F(q))", [{"p"}, {"p"}], True),
        ("G p | F q", "(G(p) | F(q))", [{"p"}, set()], False),
        ("G !r & F q", "(G(~r) & F(q))", [set(), {"q"}, set()], True),
        ("p W q", "(p W q)", [{"p"}, {"p"}], True),
        ("p W q", "(p W q)", [{"p"}, {"q"}, set()], True),
        ("p W q", "(p W q)", [{"p"}, set(), {"q"}], False),
    ],
)
def test_agrees_with_mtl_by_hand(text: str, their_text: str, trace: list, truth: bool) -> None:
    signal = {a: [(i, a in letter) for i, letter in enumerate(trace)] for a in PROPS}
    their = mtl.parse(their_text)
    assert bool(their(signal, time=0, dt=1, quantitative=False)) is truth
    assert to_dta(parse(text)).accepts_lasso(trace[:-1], trace[-1:]) is truth


# --------------------------------------------------------------------------- refused


@pytest.mark.parametrize("spec", ["G F A", "F G !B", "G !B & G F A"])
def test_models_refuse_recurrence_and_persistence_specs(spec: str, tmp_path, capsys) -> None:
    """Safety and obligation specs are solved (tests/test_safety.py); recurrence and
    persistence ones are refused where the spec is bound, in one line, by every route."""
    from mitld_lp import GridWorld, Model, ModelError, loads_model
    from mitld_lp.cli import main

    world = GridWorld.make(3, 1, start=(0, 0), regions={"A": [(2, 0)], "B": [(1, 0)]})
    with pytest.raises(ModelError, match=r"spec: 1:\d+: .* is a (recurrence|persistence) formula"):
        Model.from_game(world, spec)
    text = (f'name = "x"\nspec = "{spec}"\n[grid]\nsize = [3, 1]\nstart = [0, 0]\n'
            '[regions]\nA = [[2, 0]]\nB = [[1, 0]]\n')
    with pytest.raises(ModelError, match="(recurrence|persistence) formula"):
        loads_model(text)
    path = tmp_path / "x.toml"
    path.write_text(text)
    assert main(["solve", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "formula" in err
