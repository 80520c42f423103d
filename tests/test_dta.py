"""The translation's structure: one canonical normal form, per-call memo tables, the
record of a state's location, the cost of minimisation and the state budget.

Expected values are hand counts and a brute-force minimisation written here (Moore's
rounds of signature refinement over explicit letters), not the translation's own.
"""

from __future__ import annotations

import gc
import itertools
import json
import re
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings

import mitld_lp.automata.translate as T
from mitld_lp.automata.dta import DTA, KINDS, Location
from mitld_lp.cli import main
from mitld_lp.logic import check, nnf, parse
from mitld_lp.logic import syntax as S
from mitld_lp.logic.normal import c_and, c_or, c_until, normal_form
from mitld_lp.testing.hypothesis import formulas

PAPER = "(D[mu1] b1 & F(b1 & F[0,3] A)) | (D[mu2] b2 & F(b2 & F[0,3] B))"


def examples(n: int) -> settings:
    return settings(max_examples=n, deadline=None, suppress_health_check=list(HealthCheck))


# --------------------------------------------------------------------------- normal form


def test_canonical_form_lives_in_the_logic_layer() -> None:
    p, q = S.Prop("p"), S.Prop("q")
    # The user's form keeps F[2,5] true (it is UNKNOWN on a one-letter trace); the
    # canonical form folds it (every step has a successor).
    assert parse("F[2,5] true") == S.Until(S.TRUE, S.TRUE, S.Interval(2, 5))
    assert normal_form(nnf(parse("F[2,5] true"))) == S.TRUE
    assert c_until(S.FALSE, p, S.Interval(1, 2)) == S.FALSE
    # sorted, absorbed and joined
    assert c_and([q, p]) == c_and([p, q]) == S.And((p, q))
    assert c_or([p, c_and([p, q])]) == p
    f03, f02, f25 = (S.Until(S.TRUE, p, S.Interval(*b)) for b in ((0, 3), (0, 2), (2, 5)))
    assert c_or([f02, f03]) == f03
    assert c_or([f02, f25]) == S.Until(S.TRUE, p, S.Interval(0, 5))


@examples(150)
@given(formulas(max_depth=3, max_bound=4))
def test_canonical_constructors_ignore_operand_order(f: S.Formula) -> None:
    g = nnf(f)
    if isinstance(g, S.And | S.Or):
        make = c_and if isinstance(g, S.And) else c_or
        assert make(list(g.args)) == make(list(reversed(g.args)))


def test_to_dta_reuses_the_nnf_of_the_fragment_report(monkeypatch: pytest.MonkeyPatch) -> None:
    report = check(parse(PAPER))
    expected = T.to_dta(parse(PAPER)).n_states

    def no_second_nnf(_f: S.Formula) -> S.Formula:
        raise AssertionError("the NNF was computed again")

    monkeypatch.setattr(T, "nnf", no_second_nnf)
    d = T.to_dta(report)
    assert d.n_states == expected == 17


_DUMP = """
import json, sys
import mitld_lp.automata.translate as T
from mitld_lp.logic import parse

def dump(d):
    label = [d.location(s).label for s in range(d.n_states)]
    assert len(set(label)) == len(label)  # a state is its obligation: labels name states
    return sorted((label[s], d.is_accepting(s), d.is_rejecting(s),
                   sorted((g, label[t]) for t, g in d.guards(s).items()))
                  for s in range(d.n_states))
"""


def test_translation_keeps_no_memo_between_calls() -> None:
    """The memo tables of a translation live in one ``_Translation`` object per call:
    none survives the call, and an automaton does not depend on what was translated
    before it -- it is the one a fresh interpreter builds (compared state by state by
    their obligations, so the numbering may differ)."""
    spec = "F[0,50] p & G[0,7] (q -> F[0,3] r)"
    for other in ("F[0,3] p", "G[0,7] (q -> F[0,3] r)", "p U[0,4] r", "F[0,50] p"):
        T.to_dta(parse(other))
    T.progress(parse("F[0,3] p"), {"q"})
    gc.collect()
    assert [o for o in gc.get_objects() if isinstance(o, T._Translation)] == []
    namespace: dict = {}
    exec(_DUMP, namespace)
    here = json.loads(json.dumps(namespace["dump"](T.to_dta(parse(spec)))))
    fresh = subprocess.run(
        [sys.executable, "-c", _DUMP + f"print(json.dumps(dump(T.to_dta(parse({spec!r})))))"],
        capture_output=True, text=True, check=True, timeout=120)
    assert here == json.loads(fresh.stdout)
    assert len(here) == T.to_dta(parse(spec)).n_states > 50


# --------------------------------------------------------------------------- minimisation


def _moore_size(d: DTA) -> int:
    """Number of Myhill-Nerode classes of ``d``'s states (labelled by their kinds) by
    rounds of signature refinement over the explicit alphabet (2^atoms letters)."""
    letters = [
        frozenset(c) for r in range(len(d.atoms) + 1) for c in itertools.combinations(d.atoms, r)
    ]
    block = [KINDS.index(d.kind(s)) for s in range(d.n_states)]
    while True:
        sigs = [(block[s], tuple(block[d.step(s, a)] for a in letters)) for s in range(d.n_states)]
        ids = {sig: i for i, sig in enumerate(sorted(set(sigs)))}
        new = [ids[sig] for sig in sigs]
        if len(set(new)) == len(set(block)):
            return len(set(new))
        block = new


@examples(120)
@given(formulas(max_depth=4, max_bound=4, props=("p", "q")))
def test_the_automaton_is_minimal(f: S.Formula) -> None:
    d = T.to_dta(f, max_states=2000)
    assert _moore_size(d) == d.n_states


@pytest.mark.parametrize("k", [300, 3000])
def test_minimising_a_chain_is_not_quadratic(k: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """``F[0,k] p`` has k+3 states (k+1 windows, accept, and reject: ``F[0,0] p``
    failing leaves ``false``).  Refinement needs k rounds that each split one state off;
    recomputing every state's signature in every round is k^2 diagram walks, recomputing
    only the predecessors of the states that moved is O(k)."""
    calls = [0]
    relabel = T._relabel

    def counted(d, label):
        calls[0] += 1
        return relabel(d, label)

    monkeypatch.setattr(T, "_relabel", counted)
    d = T.to_dta(parse(f"F[0,{k}] p"))
    n = d.n_states
    assert n == k + 3
    assert calls[0] <= 30 * n


def test_state_budget_is_checked_while_a_diagram_grows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Twelve independent events: the first state's diagram alone has 2^12 successors.
    With a budget of 100 states the translation stops after O(100) combinations."""
    spec = " & ".join(f"D[geometric(0.5)] e{i} & F(e{i} & F[0,3] A)" for i in range(12))
    calls = [0]
    c_and_ = T.c_and

    def counted(args):
        calls[0] += 1
        return c_and_(args)

    monkeypatch.setattr(T, "c_and", counted)
    with pytest.raises(T.TranslationError, match="more than 100 automaton states"):
        T.to_dta(parse(spec), max_states=100)
    assert calls[0] < 2**12


# --------------------------------------------------------------------------- locations


def test_location_is_a_record() -> None:
    d = T.to_dta(parse("F[0,3] A"))
    after_one = d.step(d.initial, set())
    loc = d.location(after_one)
    assert isinstance(loc, Location)
    assert loc.obligation == "F[0,3] A"
    assert loc.clocks == (("F[0,3] A", 1),)
    assert loc.label == str(loc) == "F[0,3] A {x=1}"
    assert d.location(d.initial) == Location("F[0,3] A", (), "F[0,3] A")


@examples(120)
@given(formulas(max_depth=4, max_bound=4))
def test_location_text_is_the_label_without_clock_values(f: S.Formula) -> None:
    d = T.to_dta(f, max_states=2000)
    for s in range(d.n_states):
        loc = d.location(s)
        assert loc.obligation == re.sub(r" \{x=\d+\}", "", loc.label)
        assert loc.clocks == d.clocks(s)


def test_guards_cover_every_letter_once() -> None:
    d = T.to_dta(parse("p U[0,2] q"))
    for s in range(d.n_states):
        guards = d.guards(s)
        for letter in ({}, {"p"}, {"q"}, {"p", "q"}):
            hits = [t for t, g in guards.items() if _guard_holds(g, letter)]
            assert hits == [d.step(s, letter)]


def _guard_holds(guard: str, letter) -> bool:
    if guard == "true":
        return True
    return any(
        all((lit[1:] not in letter) if lit.startswith("!") else (lit in letter)
            for lit in term.split(" & "))
        for term in guard.split(" | ")
    )


def _equivalent_pairs(d: DTA) -> list[tuple[int, int]]:
    """The pairs of states no word tells apart, by table filling (a pair is marked when
    one accepts and the other not, or some letter leads to a marked pair), a route apart
    from :func:`_moore_size`'s rounds of refinement."""
    letters = [frozenset(c) for r in range(len(d.atoms) + 1)
               for c in itertools.combinations(d.atoms, r)]
    pairs = list(itertools.combinations(range(d.n_states), 2))
    marked = {(i, j) for i, j in pairs if d.is_accepting(i) != d.is_accepting(j)}
    changed = True
    while changed:
        changed = False
        for i, j in pairs:
            if (i, j) in marked:
                continue
            for a in letters:
                x, y = sorted((d.step(i, a), d.step(j, a)))
                if x != y and (x, y) in marked:
                    marked.add((i, j))
                    changed = True
                    break
    return [p for p in pairs if p not in marked]


@pytest.mark.parametrize(
    ("formula", "states"),
    [
        ("F[0,3] p", 6),  # windows x = 0..3, accept, reject
        ("p U[0,2] q", 5),  # windows x = 0..2, accept, reject
        # both pending at x = 0..2, only p or only q pending at x = 1, 2, accept, reject
        ("F[0,2] p & F[0,2] q", 9),
        (PAPER, 17),  # the minimal size (_moore_size agrees); 26 obligations before
    ],
)
def test_the_automaton_is_always_minimal(formula: str, states: int) -> None:
    """There is no way to skip minimisation: no two states accept the same continuations
    (Myhill-Nerode), at the hand-counted sizes (so no state is unreachable either)."""
    d = T.to_dta(parse(formula))
    assert _equivalent_pairs(d) == []
    assert d.n_states == states
    with pytest.raises(TypeError):
        T.to_dta(parse(formula), minimise=False)  # type: ignore[call-arg]


@pytest.mark.parametrize(
    ("formula", "line"),
    [
        ("F[0,3] p", "states:    6 (3 locations, 1 clock)"),
        ("true", "states:    1 (1 location, 0 clocks)"),
        (PAPER, "states:    17 (5 locations, 2 clocks)"),
    ],
)
def test_cli_dta_counts_in_words(
    formula: str, line: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["dta", formula]) == 0
    assert line in capsys.readouterr().out.splitlines()


def test_cli_dta_honours_max_states(capsys: pytest.CaptureFixture[str]) -> None:
    spec = " & ".join(f"D[geometric(0.5)] e{i} & F(e{i} & F[0,3] A)" for i in range(12))
    assert main(["dta", spec, "--max-states", "50"]) == 3  # a budget stop, not bad input
    err = capsys.readouterr().err
    assert "more than 50 automaton states" in err and err.count("\n") == 1


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_max_states_must_be_a_positive_integer(bad: object) -> None:
    with pytest.raises(T.TranslationError, match="max_states"):
        T.to_dta(parse("F p"), max_states=bad)  # type: ignore[arg-type]


def test_cli_dta_marks_the_safe_states(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dta", "G p | F q"]) == 0
    out = capsys.readouterr().out
    assert "  0 (initial) (safe): F q | false R p" in out.splitlines()
    assert out.count("(safe)") == 1 and "(accepting)" in out
    dot = T.to_dta(parse("G p | F q")).to_dot()
    assert dot.count("(safe)") == 1


def test_kinds_cover_every_state_and_persistent_is_safe_or_accept() -> None:
    d = T.to_dta(parse("G !h & (D[mu] bus & F(bus & F[0,3] stop))"))
    assert len(d.kinds) == d.n_states and set(d.kinds) <= set(KINDS)
    assert d.kind(d.rejecting) == "reject"
    assert d.persistent == {s for s in range(d.n_states) if d.kind(s) in ("safe", "accept")}
    with pytest.raises(ValueError, match="at least one letter"):
        d.accepts_lasso([], [])
