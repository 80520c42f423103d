"""cert-small: the certificate's compiled chain sets (``certify_kernels.chain_sets``
through ``certify_compiled.compiled_chain_sets``), its warm-cache load
(``certify_compiled.load_if_warm``) and a minimum's end-component test read on the
states it asks about (``certify_chain.cycling_among``).

Every bracket is held against the exact optimum computed here by brute force in
rational arithmetic (``Fraction``): every deterministic memoryless policy of a small
MDP solved exactly (the states that reach the target by Gauss-Jordan elimination, the
rest 0 by the graph), the optimum the best of them state by state (reachability has an
optimal deterministic memoryless policy for every state at once, which the
enumeration meets).  The MDPs have end components (choices that stay among the unknown
states, self-loops included) and rare probabilities near 1e-12; both senses, with the
certificate's compiled paths forced on and off (the same bits)."""

from __future__ import annotations

import itertools
from fractions import Fraction
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.sparse as sp
from test_cert_fast_exact import model_of_rows

from mitld_lp.mdp import MDP
from mitld_lp.solvers import certify as C
from mitld_lp.solvers import certify_blocks, certify_chain, certify_compiled
from mitld_lp.solvers.analysis import may_cycle
from mitld_lp.solvers.rounding import rounding
from mitld_lp.testing.exact import chain_values

RARE = (1e-12, 3e-12, 7e-13, 2.5e-12)


def small_model(seed: int, n: int) -> tuple[MDP, list[dict[int, Fraction]]]:
    """``n`` unknown states, the target ``n`` and the sink ``n + 1``.  A state's choices
    are of two kinds: one that stays among the unknown states (a self-loop, or a split
    between two of them: end components), and one that leaves to the sink and to the
    target, the target often with a rare probability near 1e-12, and maybe to other
    unknown states."""
    rng = np.random.default_rng(seed)
    target, sink = n, n + 1
    rows: list[list[dict[int, float]]] = []
    for s in range(n):
        choices = []
        for _ in range(int(rng.integers(1, 4))):
            if rng.random() < 0.35:  # stays among the unknown states
                if rng.random() < 0.5:
                    choices.append({s: 1.0})
                else:
                    a, b = (int(t) for t in rng.choice(n, size=2, replace=False))
                    p = float(rng.uniform(0.1, 0.9))
                    choices.append({a: p, b: 1.0 - p})
                continue
            succ = [int(t) for t in rng.choice(n, size=int(rng.integers(0, 3)),
                                               replace=False)]
            w = {t: float(rng.uniform(0.2, 1.0)) for t in succ}
            if rng.random() < 0.7:
                w[sink] = float(rng.uniform(0.05, 0.6))
            tail = float(rng.choice(RARE)) if rng.random() < 0.6 else float(
                rng.uniform(0.05, 0.5))
            total = sum(w.values())
            row = {t: (1.0 - tail) * p / total for t, p in w.items()} if w else {}
            row[target] = tail if w else 1.0
            choices.append(row)
        rows.append(choices)
    rows += [[], []]
    return model_of_rows(rows, target, sink)


def _policy_values(mdp: MDP, exact: list[dict[int, Fraction]], policy: tuple[int, ...]
                   ) -> list[Fraction]:
    """The exact values of ``policy`` (a row per unknown state): 0 where its chain
    cannot reach the target (a search on the graph), else ``v = P v`` with the target
    1 by Gauss-Jordan elimination in fractions (those states are transient:
    :func:`~mitld_lp.testing.exact.chain_values`)."""
    n = mdp.n_states
    target = int(np.flatnonzero(np.asarray(mdp.target))[0])
    succ = {s: [t for t, p in exact[policy[s]].items() if p > 0] if s < len(policy)
            else [] for s in range(n)}
    reach = {target}
    grew = True
    while grew:
        grew = False
        for s in range(n):
            if s not in reach and any(t in reach for t in succ[s]):
                reach.add(s)
                grew = True
    live = sorted(s for s in reach if s != target)
    step = {s: exact[policy[s]] for s in live}
    out = [Fraction(0)] * n
    out[target] = Fraction(1)
    for s, p in chain_values(step, live, target).items():
        out[s] = p
    return out


def exact_optimum(mdp: MDP, exact: list[dict[int, Fraction]], n: int, upper: bool
                  ) -> tuple[list[Fraction], np.ndarray]:
    """The optimum (``upper``: the maximum) by every deterministic policy of the ``n``
    unknown states, and a policy optimal in every state (-1 on the target and sink)."""
    groups = np.asarray(mdp.row_groups)
    solved = [(p, _policy_values(mdp, exact, p)) for p in itertools.product(
        *(range(int(groups[s]), int(groups[s + 1])) for s in range(n)))]
    pick = max if upper else min
    best = [pick(v[s] for _, v in solved) for s in range(mdp.n_states)]
    policy = next(p for p, v in solved if v == best)
    return best, np.array(list(policy) + [-1, -1], dtype=np.int64)


def paid_kernels(monkeypatch: pytest.MonkeyPatch, compiled: bool) -> None:
    """The certificate's compiled paths (the chain's sets and single levels, the
    Bellman check, the repair's needs) on or off, whatever this process loaded."""
    fake = SimpleNamespace(compiled_paid=lambda: compiled,
                           module_cached=lambda *a: False, prepare=lambda: None)
    monkeypatch.setattr(certify_compiled, "kernel_loader", fake)
    monkeypatch.setattr(certify_compiled, "COMPILED_CHECK_MIN_ROWS", 0)
    monkeypatch.setattr(certify_chain, "kernel_loader", fake)
    monkeypatch.setattr(certify_chain, "CHAIN_KERNEL_MIN_LEVELS", 0)
    # the chain's blocks' cache look-up (cert-86), fresh: never the fake's answer kept
    monkeypatch.setattr(certify_blocks, "_BLOCKS_WARM", [compiled])


N = 5
SEEDS = range(8)


@pytest.mark.parametrize("seed", SEEDS)
def test_brackets_hold_the_brute_force_optimum_compiled_or_not(seed, monkeypatch) -> None:
    mdp, exact = small_model(seed, N)
    target = np.asarray(mdp.target)
    for upper in (True, False):
        v, policy = exact_optimum(mdp, exact, N, upper)
        zero = np.array([p == 0 for p in v])
        got = []
        for compiled in (True, False):
            paid_kernels(monkeypatch, compiled)
            cert = C.certify(mdp, target, policy, sense="max" if upper else "min",
                             zero=zero, one=None if upper else np.array([p == 1 for p in v]))
            assert Fraction(cert.lower) <= v[0] <= Fraction(cert.upper), (upper, v[0])
            assert cert.certified, [c.detail for c in cert.checks]
            got.append((cert.lower.hex(), cert.upper.hex(), np.asarray(cert.values).tobytes()))
        assert got[0] == got[1]  # the compiled paths' bits are NumPy's


def test_the_models_have_end_components_and_rare_values() -> None:
    """The brute force's models are what the module docs say: some with an end
    component among the unknown states, some with an optimum below 1e-10."""
    ecs = rare = 0
    for seed in SEEDS:
        mdp, exact = small_model(seed, N)
        comp = C.support_layers(mdp)[0]
        ecs += bool(may_cycle(mdp, comp)[:N].any())
        v, _ = exact_optimum(mdp, exact, N, True)
        rare += any(0 < p < Fraction(1, 10**10) for p in v)
    assert ecs >= 4 and rare >= 2, (ecs, rare)


def chain_case(seed: int) -> tuple[sp.csr_array, np.ndarray, np.ndarray, np.ndarray]:
    """A random matrix of choices (stored zeros among the entries), a policy's row for
    each acting state, and a target."""
    rng = np.random.default_rng(seed)
    n = 60
    n_rows = 150
    data, cols, ptr = [], [], [0]
    for _ in range(n_rows):
        k = int(rng.integers(0, 4))
        succ = rng.choice(n, size=k, replace=False)
        p = rng.dirichlet(np.ones(k)) if k else np.zeros(0)
        p[rng.random(k) < 0.15] = 0.0  # stored zeros: not edges
        cols += succ.tolist()
        data += p.tolist()
        ptr.append(len(cols))
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(n_rows, n))
    target = rng.random(n) < 0.08
    acting = (rng.random(n) < 0.9) & ~target
    states = np.flatnonzero(acting)
    return m, states, rng.integers(0, n_rows, size=states.size), target


def sets_by_fixpoint(m: sp.csr_array, states: np.ndarray, rows: np.ndarray,
                      target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``never`` and ``sure`` by a forward fixpoint on a dense boolean adjacency (a
    route that shares nothing with either search)."""
    n = target.size
    adj = np.zeros((n, n), dtype=bool)
    for s, r in zip(states, rows, strict=True):
        a, z = m.indptr[r], m.indptr[r + 1]
        adj[s, m.indices[a:z][m.data[a:z] > 0]] = True

    def reaches(seeds: np.ndarray) -> np.ndarray:
        got = seeds.copy()
        while True:
            more = got | adj[:, got].any(axis=1)
            if np.array_equal(more, got):
                return got
            got = more

    never = ~reaches(target)
    return never, ~reaches(never)


@pytest.mark.parametrize("seed", range(10))
def test_compiled_chain_sets_are_the_searches(seed, monkeypatch) -> None:
    m, states, rows, target = chain_case(seed)
    want = sets_by_fixpoint(m, states, rows, target)
    paid_kernels(monkeypatch, False)
    assert certify_compiled.compiled_chain_sets(m, states, rows, target) is None
    numpy = certify_chain._sets(m, target.size, states, rows, target, np.int32)
    paid_kernels(monkeypatch, True)
    got = certify_compiled.compiled_chain_sets(m, states, rows, target)
    assert got is not None
    for a, b, c in zip(want, numpy, got, strict=True):
        assert np.array_equal(a, b) and np.array_equal(a, c)
    # the chain itself decides the same sets through either path
    assert np.array_equal(certify_chain._sets(m, target.size, states, rows, target,
                                              np.int32)[1], want[1])


def _mdp_of(m: sp.csr_array, groups: np.ndarray) -> SimpleNamespace:
    """What :func:`~mitld_lp.solvers.analysis.may_cycle` reads of an MDP."""
    owner = np.repeat(np.arange(groups.size - 1), np.diff(groups))
    return SimpleNamespace(matrix=m, state_of=lambda c: owner[c], choice_state=lambda: owner)


@pytest.mark.parametrize("seed", range(10))
def test_cycling_among_is_may_cycle_on_the_states_asked(seed) -> None:
    rng = np.random.default_rng(seed)
    n = 50
    per = rng.integers(0, 4, size=n)
    groups = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    data, cols, ptr = [], [], [0]
    for s in range(n):
        for _ in range(int(per[s])):
            kind = rng.random()
            if kind < 0.2:  # stays put: every entry in its own column
                succ = np.array([s] * int(rng.integers(1, 3)))
            elif kind < 0.3:  # first entry its own, then another: not staying
                succ = np.array([s, (s + 1 + int(rng.integers(0, n - 1))) % n])
            else:
                succ = np.sort(rng.choice(n, size=int(rng.integers(0, 3)), replace=False))
            cols += succ.tolist()
            data += [1.0 / max(succ.size, 1)] * succ.size
            ptr.append(len(cols))
    m = sp.csr_array((np.array(data), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(int(groups[-1]), n))
    comp = certify_chain.support_layers(SimpleNamespace(matrix=m, row_groups=groups))[0]
    left = rng.random(n) < 0.6
    want = left & may_cycle(_mdp_of(m, groups), comp)
    assert np.array_equal(certify_chain.cycling_among(m, groups, comp, left), want)


def test_load_if_warm_pays_only_a_warm_cheap_load(monkeypatch) -> None:
    calls = []
    state = {"paid": False, "warm": True}

    def prepare() -> None:
        calls.append(1)
        state["paid"] = True

    fake = SimpleNamespace(compiled_paid=lambda: state["paid"],
                           module_cached=lambda *a: state["warm"], prepare=prepare)
    monkeypatch.setattr(certify_compiled, "kernel_loader", fake)
    big = certify_compiled.WARM_LOAD_MIN_ENTRIES
    monkeypatch.setattr(certify_compiled, "_WARM", [])
    assert not certify_compiled.load_if_warm(big - 1) and not calls  # small: never
    state["warm"] = False  # a cold cache (or the loader off, numba missing): never
    assert not certify_compiled.load_if_warm(big) and not calls
    monkeypatch.setattr(certify_compiled, "_WARM", [])
    state["warm"] = True
    assert certify_compiled.load_if_warm(big) and calls == [1]
    assert certify_compiled.load_if_warm(1) and calls == [1]  # paid: nothing more


def test_a_disabled_loader_is_never_warm(monkeypatch) -> None:
    from mitld_lp.util import kernel_loader

    monkeypatch.setattr(kernel_loader, "ENABLED", False)
    assert not any(kernel_loader.module_cached(mod, name)
                   for mod, name in certify_compiled.WARM_KERNELS)


def test_the_chain_of_a_certificate_is_the_same_compiled_or_not(monkeypatch) -> None:
    """The whole chain (its sets, values and slack) on a model with end components,
    compiled paths on and off: the same bits."""
    mdp, exact = small_model(3, N)
    v, policy = exact_optimum(mdp, exact, N, True)
    rnd = rounding(sp.csr_array(mdp.matrix))
    got = []
    for compiled in (True, False):
        paid_kernels(monkeypatch, compiled)
        ch = C.chain(mdp, np.asarray(mdp.target), policy, rnd)
        got.append([np.asarray(a).tobytes() for a in (ch.values, ch.w, ch.solved,
                                                      ch.sure, ch.never)])
        # the policy's exact value is inside the chain's float value's reach
        assert ch.sure[int(np.flatnonzero(np.asarray(mdp.target))[0])]
    assert got[0] == got[1]


def _attractor_by_fixpoint(m: sp.csr_array, groups: np.ndarray, seeds: np.ndarray
                           ) -> np.ndarray:
    """The states from which every policy reaches ``seeds`` with positive probability
    (a state with no choice only if a seed), by the plain fixpoint: a state joins when
    every one of its choices has an entry into the set."""
    got = seeds.copy()
    while True:
        more = got.copy()
        for s in np.flatnonzero(~got):
            rows = range(int(groups[s]), int(groups[s + 1]))
            more[s] = len(rows) > 0 and all(
                got[m.indices[m.indptr[r]:m.indptr[r + 1]]].any() for r in rows)
        if np.array_equal(more, got):
            return got
        got = more


@pytest.mark.parametrize("seed", range(12))
def test_attracted_compiled_or_not_is_the_fixpoint(seed, monkeypatch) -> None:
    rng = np.random.default_rng(seed)
    n = 40
    per = rng.integers(1, 3, size=n)
    groups = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    cols, ptr = [], [0]
    for _ in range(int(groups[-1])):
        cols += np.sort(rng.choice(n, size=int(rng.integers(1, 3)), replace=False)).tolist()
        ptr.append(len(cols))
    m = sp.csr_array((np.full(len(cols), 0.5), np.array(cols, dtype=np.int32),
                      np.array(ptr, dtype=np.int32)), shape=(int(groups[-1]), n))
    inside = rng.random(n) < (0.3 + 0.05 * (seed % 6))
    want = bool(_attractor_by_fixpoint(m, groups, ~inside)[inside].all())
    got = []
    for compiled in (True, False):
        paid_kernels(monkeypatch, compiled)
        got.append(certify_chain.attracted(m, groups, inside))
    assert got == [want, want]
