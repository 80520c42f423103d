"""The greedy check's compiled dual-feasibility pass (mitld_lp.solvers.greedy_kernels):
its decisions are those of sums in long double written here apart (a choice's products
added one by one in ``numpy.longdouble``), a decision float64 cannot take is left to
that route (UNSURE), and through ``certified_greedy`` the compiled route and the long
double batches give the same policy, values and failing states; a policy that is not
dual feasible is refused with the compiled pass too."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from mitld_lp.solvers import greedy_block, lp_blocks
from mitld_lp.solvers.graph import Sense
from mitld_lp.solvers.greedy_block import certified_greedy
from mitld_lp.solvers.quotient import reduce
from mitld_lp.solvers.topological import Block
from mitld_lp.testing import random_mdp

kernels = pytest.importorskip("mitld_lp.solvers.greedy_kernels")


@pytest.fixture(autouse=True)
def _compiled(monkeypatch: pytest.MonkeyPatch) -> None:
    """The compiled pass on blocks of any size (the package takes it from
    KERNEL_MIN_CHOICES choices on, once the kernels' load is paid)."""
    from mitld_lp.util import kernel_loader

    kernel_loader.prepare()
    monkeypatch.setattr(greedy_block, "KERNEL_MIN_CHOICES", 0)
    monkeypatch.setattr(lp_blocks, "GREEDY_MIN_CHOICES", 0)


def _slack_ld(indptr, indices, data, reward, raw, c, s, maximise) -> np.float64:
    """Choice ``c``'s slack at state ``s``, its score summed in long double term by
    term, rounded to float64."""
    acc = np.longdouble(0.0)
    for e in range(indptr[c], indptr[c + 1]):
        acc += np.longdouble(data[e]) * np.longdouble(raw[indices[e]])
    score = np.longdouble(reward[c]) + acc
    gain = score - np.longdouble(raw[s]) if maximise else np.longdouble(raw[s]) - score
    return np.float64(-gain)


def _reference(indptr, indices, data, groups, reward, raw, tie, chosen, maximise):
    """Per state, whether a choice beats the policy (``tie + slack < 0``) or its own
    residual is above ``tie``, by :func:`_slack_ld`."""
    failed = np.zeros(groups.size - 1, dtype=bool)
    for s in range(groups.size - 1):
        for c in range(groups[s], groups[s + 1]):
            slack = _slack_ld(indptr, indices, data, reward, raw, c, s, maximise)
            if tie[s] + slack < 0.0 or (c == chosen[s] and abs(slack) > tie[s]):
                failed[s] = True
    return failed


def _slack_f64(indptr, indices, data, reward, raw, c, s, maximise):
    acc = 0.0
    for e in range(indptr[c], indptr[c + 1]):
        acc += float(data[e]) * float(raw[indices[e]])
    score = float(reward[c]) + acc
    return raw[s] - score if maximise else score - raw[s]


@pytest.mark.parametrize("maximise", [True, False])
@pytest.mark.parametrize("seed", range(3))
def test_kernel_decides_as_long_double_sums(seed: int, maximise: bool) -> None:
    """Random rows of many terms (float64 and long double sums differ in their last
    bits).  States of several choices with a tie scale that fails some of them; states
    of one choice whose tie scale is set on the long double slack itself, where float64
    alone would refuse the policy and the long double route does not: every decision
    the kernel takes is the long double one, and those borderline states are UNSURE."""
    rng = np.random.default_rng(seed)
    n = 80
    per = np.where(np.arange(n) % 2 == 0, 1, rng.integers(2, 4, size=n))
    groups = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)
    m = int(groups[-1])
    k = rng.integers(5, 40, size=m)
    indptr = np.concatenate([[0], np.cumsum(k)]).astype(np.int64)
    indices = np.concatenate([np.sort(rng.choice(n, size=j, replace=False)) for j in k])
    data = np.concatenate([rng.dirichlet(np.ones(j)) * 0.9 for j in k])
    reward = rng.random(m) * 0.1
    raw = rng.random(n)
    chosen = groups[:-1] + rng.integers(0, per)
    tie = np.full(n, 0.3)
    borderline = []
    for s in np.flatnonzero(per == 1):
        c = groups[s]
        ld = _slack_ld(indptr, indices, data, reward, raw, c, s, maximise)
        if _slack_f64(indptr, indices, data, reward, raw, c, s, maximise) < ld < 0.0:
            tie[s] = -ld  # long double: neither beaten nor off; float64 alone: beaten
            borderline.append(s)
    assert borderline, "no row whose float64 slack is below its long double one"
    flag = kernels.dual_check(indptr, indices, data, groups, reward, raw, tie, chosen,
                              maximise)
    want = _reference(indptr, indices, data, groups, reward, raw, tie, chosen, maximise)
    sure = flag != kernels.UNSURE
    np.testing.assert_array_equal(flag[sure] == kernels.FAILED, want[sure])
    assert not want[borderline].any()
    assert (flag[borderline] == kernels.UNSURE).all()
    assert want.any() and sure.sum() > n // 2  # failures, most decided by float64


def _same(got, want) -> None:
    """Both refused, or the same policy, values and states left to the LP."""
    assert (got is None) == (want is None)
    if got is not None:
        for a, b in ((got.chosen, want.chosen), (got.values, want.values),
                     (got.left, want.left)):
            assert a.tobytes() == b.tobytes()


def _block(seed: int) -> tuple[Block, np.ndarray]:
    mdp = random_mdp(300, seed=seed, target_fraction=0.05, sink_fraction=0.05,
                     self_loop_fraction=0.0, max_choices=4, max_successors=4)
    q = reduce(mdp, mdp.target)
    return Block.of(q, np.arange(q.n_states)), q.to_target


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(4))
def test_certified_greedy_same_with_and_without_the_pass(seed: int, sense: Sense,
                                                         monkeypatch) -> None:
    """Bounds that leave some states failing and some settled: the compiled pass and
    the long double batches settle the same states with the same policy and values."""
    block, _ = _block(seed)
    rng = np.random.default_rng(seed)
    bound = rng.random(block.states.size) * 0.5
    reward = block.to_target.copy()
    got = certified_greedy(block, reward.copy(), bound, sense, 1e-9, 1e-6)
    monkeypatch.setattr(greedy_block, "_paid", lambda m: False)
    want = certified_greedy(block, reward.copy(), bound, sense, 1e-9, 1e-6)
    _same(got, want)


@pytest.mark.parametrize("sense", [Sense.MAX, Sense.MIN])
@pytest.mark.parametrize("seed", range(3))
def test_greedy_choices_are_segmented_argmaxs(seed: int, sense: Sense) -> None:
    """The compiled greedy choice is SciPy's product and segmented_argmax's pick, tied
    choices included (every choice has an exact copy: the lowest index wins)."""
    from mitld_lp.solvers.graph import segmented_argmax

    block, _ = _block(seed)
    rows = block.inner
    twice = np.repeat(np.arange(rows.shape[0]), 2)  # each choice and its copy
    inner = sp.csr_array(rows[twice])
    groups = 2 * block.groups
    reward = np.repeat(block.to_target, 2)
    bound = np.random.default_rng(seed).random(block.states.size)
    want = segmented_argmax(reward + inner @ bound, groups, sense=sense)
    got = kernels.greedy_choices(inner.indptr, inner.indices, inner.data, groups,
                                 reward, bound, sense is Sense.MAX)
    np.testing.assert_array_equal(got, want)
    assert np.all(got % 2 == 0)  # the first of two tied copies


def test_the_pass_is_taken_and_fails_states(monkeypatch) -> None:
    """The pass runs on these blocks and refuses states there (else the test above
    would only compare the long double route with itself on passes)."""
    seen: list[np.ndarray] = []
    real = kernels.dual_check

    def spy(*args):
        flag = real(*args)
        seen.append(flag)
        return flag

    monkeypatch.setattr(kernels, "dual_check", spy)
    block, _ = _block(0)
    bound = np.random.default_rng(0).random(block.states.size) * 0.5
    certified_greedy(block, block.to_target.copy(), bound, Sense.MAX, 1e-9, 1e-6)
    assert seen and (seen[0] == kernels.FAILED).any()


def test_an_unsorted_block_is_left_as_it_came(monkeypatch) -> None:
    """A block whose rows list their columns out of order: the compiled check reads a
    sorted copy (as the long double route sums them) and leaves the block's own rows
    alone; both routes settle the same."""
    block, _ = _block(1)
    rows = block.inner
    order = np.concatenate([np.arange(rows.indptr[c], rows.indptr[c + 1])[::-1]
                            for c in range(rows.shape[0])])
    unsorted = sp.csr_array((rows.data[order], rows.indices[order], rows.indptr),
                            shape=rows.shape)
    block = Block(block.states, block.choices, unsorted, block.outer, block.starts,
                  block.to_target)
    before = unsorted.indices.copy()
    bound = np.random.default_rng(1).random(block.states.size) * 0.5
    got = certified_greedy(block, block.to_target.copy(), bound, Sense.MAX, 1e-9, 1e-6)
    np.testing.assert_array_equal(unsorted.indices, before)
    monkeypatch.setattr(greedy_block, "_paid", lambda m: False)
    want = certified_greedy(block, block.to_target.copy(), bound, Sense.MAX, 1e-9, 1e-6)
    _same(got, want)


def test_a_policy_not_dual_feasible_is_refused() -> None:
    """A two-state cycle in which the bounds rank a losing choice first (the hand block
    of test_greedy_block, in Fractions there): v0 = v1 = 1/2 is the optimum; with
    bounds 0.4, s1's choice of 49/100 is greedy and loses to 1/3 + v0/3; the pass
    refuses it, and certifies the policy of bounds 0.499."""
    rows = [[0, 0.5], [0, 0.5], [0, 0], [1 / 3, 0], [1 / 3, 0], [0, 0]]
    reward = np.array([0.25, 0.25, 0.2, 1 / 3, 1 / 3, 0.49])
    inner = sp.csr_array(np.array(rows))
    block = Block(np.arange(2), np.arange(6), inner, inner, np.array([0, 3]), reward)
    assert certified_greedy(block, reward.copy(), np.array([0.4, 0.4]), Sense.MAX,
                            1e-9, 1e-6) is None
    ok = certified_greedy(block, reward.copy(), np.array([0.499, 0.499]), Sense.MAX,
                          1e-9, 1e-6)
    assert ok is not None and ok.left.size == 0
    np.testing.assert_allclose(ok.values, [0.5, 0.5], rtol=1e-15)
