"""cert-lean2: the certificate's brackets after its lean changes (the policy's side by
SciPy's product on rows gathered once, the chain's values kept on its solved states
and made for every state last, the chain walk's upstream order made only when a
transposed solve asks) held against exact values computed here.

The exact values come from the model in rational arithmetic (each stored row's floats as
fractions divided by their exact sum), solved by a small exact solver written here:
policy iteration whose evaluations are Gauss-Jordan eliminations in ``Fraction``s (the
models leave no end component among the unknown states: every choice leaks to the sink
or the target, so every policy is proper and the optimum is the unique fixed point),
confirmed by one exact Bellman step.  The models: small cyclic MDPs with rare events
(probabilities 1e-12 and 1e-13 to the target) and deep chains (300 states in a line,
and a 120-state birth-death chain whose values fall geometrically).  Each bracket must
hold the exact optimum: ``lower <= exact <= upper``, in both senses."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_policy, chain_levels
from mitld_lp.solvers.analysis import analyse
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.iteration import interval_iteration
from mitld_lp.solvers.lp import solve_lp

RARE = (1e-12, 3e-13, 1e-13)


# ------------------------------------------------------------------ models


def _mdp(rows: list[list[dict[int, float]]], target: int, sink: int) -> MDP:
    """The MDP whose states' choices are ``rows`` (a dict of successor to probability a
    choice; the target and the sink one self-loop each)."""
    n = len(rows)
    data, cols, ptr, groups, acts = [], [], [0], [0], []
    for s, choices in enumerate(rows):
        for k, c in enumerate(choices or [{s: 1.0}]):
            for t in sorted(c):
                cols.append(t)
                data.append(c[t])
            ptr.append(len(cols))
            acts.append(ABSORB if not choices else k % 2)
        groups.append(len(ptr) - 1)
    matrix = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                           np.array(ptr, dtype=np.int32)), shape=(len(ptr) - 1, n))
    tgt = np.zeros(n, dtype=bool)
    tgt[target] = True
    snk = np.zeros(n, dtype=bool)
    snk[sink] = True
    return MDP(matrix=matrix, row_groups=np.array(groups, dtype=np.int64),
               choice_actions=np.array(acts, dtype=np.int32), action_names=("a", "b"),
               initial=0, target=tgt, sink=snk, truncated=np.zeros(n, dtype=bool),
               states=list(range(n)))


def _rare_cyclic(seed: int, n: int) -> MDP:
    """``n`` unknown states, the target ``n`` and the sink ``n + 1``; each choice goes to
    the target with a rare probability (:data:`RARE`), to the sink
    with at least 0.05 (no end component among the unknown states), and to up to
    three unknown states, itself included."""
    rng = np.random.default_rng(seed)
    target, sink = n, n + 1
    rows: list[list[dict[int, float]]] = []
    for _s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            succ = [int(t) for t in rng.choice(n, size=int(rng.integers(1, 4)),
                                               replace=False)]
            w = {t: float(rng.uniform(0.1, 1.0)) for t in succ}
            w[sink] = float(rng.uniform(0.05, 0.5))
            tail = float(rng.choice(RARE))
            total = sum(w.values())
            row = {t: (1.0 - tail) * p / total for t, p in w.items()}
            row[target] = tail
            choices.append(row)
        rows.append(choices)
    return _mdp(rows + [[], []], target, sink)


def _deep_line(n: int) -> MDP:
    """A line of ``n`` states: from state ``s`` a careful choice (forward with 0.99, the
    sink 0.01 - 1e-12, the target 1e-12) and a bold one (forward 0.9, the target
    2e-12, the sink the rest); the last state goes to the target with 1e-12 and the
    sink otherwise."""
    target, sink = n, n + 1
    rows: list[list[dict[int, float]]] = []
    for s in range(n):
        nxt = s + 1 if s + 1 < n else sink
        careful = {nxt: 0.99, sink: 0.01 - 1e-12, target: 1e-12} if nxt != sink else \
            {sink: 1.0 - 1e-12, target: 1e-12}
        bold = {nxt: 0.9, sink: 0.1 - 2e-12, target: 2e-12} if nxt != sink else \
            {sink: 1.0 - 2e-12, target: 2e-12}
        rows.append([careful, bold])
    return _mdp(rows + [[], []], target, sink)


def _birth_death(n: int) -> MDP:
    """A birth-death chain of ``n`` states: from ``s`` up with 0.3 (the last state: to
    the target with 0.3), down with 0.6 (state 0: to the sink), the sink 0.1; a second
    choice in every third state that goes up with 0.35 and leaks 0.15 to the sink.
    Its values fall geometrically from the top (about 0.5 a state): deep and cyclic."""
    target, sink = n, n + 1
    rows: list[list[dict[int, float]]] = []
    for s in range(n):
        up = s + 1 if s + 1 < n else target
        down = s - 1 if s > 0 else sink
        first = {up: 0.3, down: 0.6}
        first[sink] = first.get(sink, 0.0) + 0.1
        choices = [first]
        if s % 3 == 0:
            second = {up: 0.35, down: 0.5}
            second[sink] = second.get(sink, 0.0) + 0.15
            choices.append(second)
        rows.append(choices)
    mdp = _mdp(rows + [[], []], target, sink)
    # the initial state at the bottom: its value some 1e-40 (rare, and deep)
    return mdp


# ------------------------------------------------------------------ the exact solver


def _exact_rows(mdp: MDP) -> list[dict[int, Fraction]]:
    """Each stored row in rational arithmetic, divided by its exact sum."""
    m = mdp.matrix
    out = []
    for r in range(m.shape[0]):
        a, z = int(m.indptr[r]), int(m.indptr[r + 1])
        row = {int(t): Fraction(float(p)) for t, p in zip(m.indices[a:z], m.data[a:z],
                                                         strict=True)}
        total = sum(row.values())
        out.append({t: p / total for t, p in row.items()})
    return out


def _evaluate(n: int, rows: list[dict[int, Fraction]], policy: list[int],
              target: int, sink: int) -> list[Fraction]:
    """The exact values of ``policy`` (a row a state; the target 1, the sink 0): the
    system ``v(s) - sum_t P(s, t) v(t) = P(s, target)`` on the other states, solved by
    sparse Gaussian elimination in fractions, rows as dicts, then back substitution.
    Every row leaks to the sink, so ``I - P`` is strictly diagonally dominant by rows:
    its pivots in the natural order are positive."""
    live = [s for s in range(n) if s not in (target, sink)]
    at = {s: i for i, s in enumerate(live)}
    k = len(live)
    a: list[dict[int, Fraction]] = []
    b: list[Fraction] = []
    below: dict[int, set[int]] = {}  # column -> the rows after it holding it
    for i, s in enumerate(live):
        row = {i: Fraction(1)}
        rhs = Fraction(0)
        for t, p in rows[policy[s]].items():
            if t == target:
                rhs += p
            elif t != sink:
                row[at[t]] = row.get(at[t], Fraction(0)) - p
        row = {c: x for c, x in row.items() if x != 0}
        a.append(row)
        b.append(rhs)
        for c in row:
            if c < i:
                below.setdefault(c, set()).add(i)
    for c in range(k):
        piv = a[c][c]
        assert piv > 0
        for r in sorted(below.pop(c, ())):
            f = a[r].pop(c) / piv
            for col, x in a[c].items():
                if col == c:
                    continue
                got = a[r].get(col, Fraction(0)) - f * x
                if got:
                    a[r][col] = got
                    if col < r:
                        below.setdefault(col, set()).add(r)
                else:
                    a[r].pop(col, None)
            b[r] -= f * b[c]
    x = [Fraction(0)] * k
    for i in range(k - 1, -1, -1):
        acc = b[i] - sum((v * x[c] for c, v in a[i].items() if c > i), Fraction(0))
        x[i] = acc / a[i][i]
    v = [Fraction(0)] * n
    v[target] = Fraction(1)
    for i, s in enumerate(live):
        v[s] = x[i]
    return v


def _exact_optimum(mdp: MDP, maximum: bool) -> list[Fraction]:
    """The exact optimum by policy iteration (a choice changes only where another is
    strictly better), confirmed a fixed point of the exact Bellman operator."""
    rows = _exact_rows(mdp)
    n, groups = mdp.n_states, np.asarray(mdp.row_groups)
    target = int(np.flatnonzero(mdp.target)[0])
    sink = int(np.flatnonzero(mdp.sink)[0])
    better = (lambda a, b: a > b) if maximum else (lambda a, b: a < b)  # noqa: E731

    def value(r: int, v: list[Fraction]) -> Fraction:
        return sum((p * v[t] for t, p in rows[r].items()), Fraction(0))

    policy = [int(groups[s]) for s in range(n)]
    while True:
        v = _evaluate(n, rows, policy, target, sink)
        changed = False
        for s in range(n):
            if s in (target, sink):
                continue
            for r in range(int(groups[s]), int(groups[s + 1])):
                if better(value(r, v), value(policy[s], v)):
                    policy[s], changed = r, True
        if not changed:
            break
    for s in range(n):  # one exact Bellman step leaves it where it is
        if s not in (target, sink):
            pick = max if maximum else min
            assert pick(value(r, v) for r in range(int(groups[s]),
                                                   int(groups[s + 1]))) == v[s]
    return v


# ------------------------------------------------------------------ the certificate


def _certified(mdp: MDP, sense: Sense) -> C.Certificate:
    """The certificate of ``mdp``'s LP policy, as the plain route asks for it."""
    it = interval_iteration(mdp, mdp.target, sense=sense, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, sense=sense, everywhere=True,
                  bounds=(it.lower, it.upper), greedy=False)
    q, _ = analyse(mdp, mdp.target, sense=sense)
    low = sense is Sense.MIN
    return C.certify(mdp, mdp.target, lp.policy, sense=str(sense),
                     zero=q.qualitative.zero, one=q.qualitative.one if low else None,
                     mec_of=None if low else q.mecs.mec_of, layers=q.layers,
                     fallback_lower=it.lower, fallback_upper=it.upper, precision=1e-6)


def _holds(cert: C.Certificate, exact: Fraction) -> None:
    assert Fraction(cert.lower) <= exact <= Fraction(cert.upper), (
        cert.lower, float(exact), cert.upper)
    assert cert.certified, [c.detail for c in cert.checks]
    # tight as well as sound: within a millionth of the exact value
    assert Fraction(cert.upper) - Fraction(cert.lower) <= exact / 10**6


MODELS = {
    **{f"rare{seed}": (lambda seed=seed: _rare_cyclic(seed, 14)) for seed in range(6)},
    "line300": lambda: _deep_line(300),
    "birth_death120": lambda: _birth_death(120),
}


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
def test_the_bracket_holds_the_exact_optimum(name: str, sense: Sense) -> None:
    mdp = MODELS[name]()
    exact = _exact_optimum(mdp, sense is Sense.MAX)
    s0 = int(mdp.initial)
    assert 0 < exact[s0] < Fraction(1, 10**6)  # a rare event, not one the graph decides
    _holds(_certified(mdp, sense), exact[s0])


@pytest.mark.parametrize("name", ["rare0", "rare3", "line300"])
def test_the_certificates_values_are_the_policys_exact_values(name: str) -> None:
    """``Certificate.values`` (made for every state after the sides' checks, from the
    solved states' values and the chain's sets): each state's float within 1e-9
    (relative) of the exact value of the policy played, 1 on the target, 0 on the
    sink, every state."""
    mdp = MODELS[name]()
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                  greedy=False)
    q, _ = analyse(mdp, mdp.target)
    cert = C.certify(mdp, mdp.target, lp.policy, zero=q.qualitative.zero,
                     mec_of=q.mecs.mec_of, layers=q.layers, fallback_lower=it.lower,
                     fallback_upper=it.upper, precision=1e-6)
    target = int(np.flatnonzero(mdp.target)[0])
    sink = int(np.flatnonzero(mdp.sink)[0])
    groups = np.asarray(mdp.row_groups)
    policy = [int(r) if r >= 0 else int(groups[s]) for s, r in enumerate(lp.policy)]
    exact = _evaluate(mdp.n_states, _exact_rows(mdp), policy, target, sink)
    assert cert.values.shape == (mdp.n_states,) and not cert.values.flags.writeable
    for s in range(mdp.n_states):
        got = Fraction(float(cert.values[s]))
        assert abs(got - exact[s]) <= exact[s] / 10**9, (s, float(got), float(exact[s]))


def test_the_policy_rows_product_sums_as_a_python_loop(monkeypatch) -> None:
    """The policy side's sums (SciPy's CSR product on the rows gathered once) are the
    sums of a Python loop from 0 in each row's stored order, bit for bit; and without
    SciPy's product (``rows_dot``) the same bits."""
    mdp = _rare_cyclic(2, 40)
    m = sp.csr_array(mdp.matrix)
    rng = np.random.default_rng(5)
    rows = rng.integers(0, m.shape[0], size=60)
    x = rng.random(m.shape[1]) * np.where(rng.random(m.shape[1]) < 0.3, 1e-12, 1.0)
    want = []
    for r in rows.tolist():
        acc = 0.0
        for e in range(int(m.indptr[r]), int(m.indptr[r + 1])):
            acc += float(m.data[e]) * float(x[m.indices[e]])
        want.append(acc)
    got = certify_policy._RowsProduct(m, rows)(x)
    assert got.tobytes() == np.array(want).tobytes()
    monkeypatch.setattr(certify_policy, "sparsetools", None)
    fallback = certify_policy._RowsProduct(m, rows)
    assert fallback.ptr is None
    assert fallback(x).tobytes() == np.array(want).tobytes()


def test_the_walks_upstream_order_is_the_stable_sort_by_level(monkeypatch) -> None:
    """The single states upstream first (made at the first transposed solve only) are
    those of a stable sort by decreasing level; the transposed solve of a walked chain
    (a line with back edges and cycles, walked over its components) is the dense
    solve of ``x = rhs + Q^T x``; a forward solve leaves the upstream order unmade."""
    monkeypatch.setattr(chain_levels, "WALK_MIN_STATES", 8)
    rng = np.random.default_rng(3)
    n = 400
    dense = np.zeros((n, n))
    for s in range(n):
        for t in rng.choice(np.arange(s + 1, min(n, s + 6)), size=min(2, n - s - 1),
                            replace=False) if s + 1 < n else []:
            dense[s, t] = 0.3
        if s % 17 == 5:  # a cycle now and then: a back edge within a few states
            dense[s, s - 3] = 0.2
        if s % 23 == 0:
            dense[s, s] = 0.1  # a self-loop
    walk = chain_levels.ChainLevels(sp.csr_array(dense))
    assert walk.blocks is not None
    rhs = rng.random(n)
    forward = walk.solve(rhs)
    assert walk._upstream is None  # a forward solve alone: no upstream order made
    assert np.allclose(forward, np.linalg.solve(np.eye(n) - dense, rhs), rtol=1e-12)
    back = walk.solve_transposed(rhs)
    assert np.allclose(back, np.linalg.solve(np.eye(n) - dense.T, rhs), rtol=1e-12)
    if walk._kernels is not None:
        assert walk._upstream is not None
    blk = walk.blocks
    states, at, _ = walk._runs()
    level_of = np.repeat(np.arange(blk.n_levels), np.diff(at))
    want = states[np.argsort(-level_of, kind="stable")]
    assert np.array_equal(walk._upstream_singles(), want)


@pytest.mark.parametrize("name,halved", [("line300", True), ("rare1", False),
                                         ("rare4", False)])
@pytest.mark.parametrize("sparse", [True, False])
def test_a_repaired_upper_bound_holds_the_exact_maximum(name: str, halved: bool,
                                                       sparse: bool, monkeypatch) -> None:
    """The upper candidate made to fail and repaired (every level read state by state,
    ``SPARSE_LEVEL`` 1, or by the walk's slices): on the line, the policy's chain values
    halved (each level a state: the repair lifts them level by level); on the cyclic
    models, the chain's float values without their slack ``W`` (the policy's ties and
    rounding fail by a few units in the last place, the cycles taken up round after
    round).  The checked bound passes and is at least the exact maximum in every
    state; both ways give the same bound, bit for bit."""
    from mitld_lp.solvers import certify_chain, certify_repair

    mdp = MODELS[name]()
    exact = _exact_optimum(mdp, True)
    it = interval_iteration(mdp, mdp.target, gap="max", progress=False)
    lp = solve_lp(mdp, mdp.target, everywhere=True, bounds=(it.lower, it.upper),
                  greedy=False)
    q, _ = analyse(mdp, mdp.target)
    rnd = C.rounding(mdp.matrix)
    ch = C.chain(mdp, np.asarray(q.target), lp.policy, rnd, q.layers)
    low = certify_chain.Chain(ch.v * 0.5 if halved else ch.v,
                              ch.w if halved else 0.0 * ch.w, ch.solved, ch.sure,
                              ch.never, ch.policy, ch.target)
    sides = []
    for level in (1, 1 << 30) if sparse else (1 << 30,):
        monkeypatch.setattr(certify_repair, "SPARSE_LEVEL", level)
        sides.append(C.optimum_upper(mdp, low, rnd, zero=q.qualitative.zero,
                                     layers=q.layers, mec_of=q.mecs.mec_of))
    side = sides[0]
    assert side.check.passed and "repaired" in side.check.detail, side.check.detail
    for s in range(mdp.n_states):
        assert Fraction(float(side.vector[s])) >= exact[s], s
    if sparse:
        assert sides[0].vector.tobytes() == sides[1].vector.tobytes()
