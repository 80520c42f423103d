"""The sensed build's level kernels (:func:`mitld_lp.sensing.group_kernels.level_hypotheses`:
a level's hypotheses grouped, summed, weighed and hashed in one pass, its sums decided as
:func:`mitld_lp.sensing.rows.fsum_by` decides them and its unsure ones by CPython's
``math.fsum`` algorithm; :func:`~mitld_lp.sensing.group_kernels.by_observation_bits`: the
observations as one word from their known widths) against answers found another way:
the hypotheses of random rows grouped with Python dictionaries and tuples, summed with
Python floats in the rows' order and totalled by :func:`math.fsum` (also on sums built
to fall half-way between two floats), hashed with Python integers; and whole products
of small random cases against the one-state-at-a-time build of
tests/test_sensing_build.py (an enumeration written apart) and against the NumPy lines
(the build without the kernels), to the bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_sensing_build import assert_same, reference, with_sensors

from mitld_lp.automata.translate import to_dta
from mitld_lp.sensing import Sensor, rows
from mitld_lp.sensing.belief import belief_product

pytest.importorskip("numba")
gk = pytest.importorskip("mitld_lp.sensing.group_kernels")

MASK = (1 << 64) - 1


def mixed(x: int) -> int:
    """splitmix64's finaliser of ``x`` with Python integers (rows.mix64's)."""
    z = (x + 0x9E3779B97F4A7C15) & MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
    return z ^ (z >> 31)


def by_hand(obs: list[int], tid: list[int], q: list[int], mass: list[float],
            s_seq: list[int], rank: list[int], nq: int) -> dict[str, list]:
    """What a level's hypotheses are, written plainly: per observation its hypotheses
    (distinct ``rank[tid] * nq + q``) in ascending order, each one's mass summed in the
    rows' order, the observation's total by math.fsum, the weights, the count, the hash
    (the sum of the codes' mixes, modulo 2**64) and the least ``s_seq``."""
    sums: dict[tuple[int, int], float] = {}
    code: dict[tuple[int, int], int] = {}
    for o, t, a, m in zip(obs, tid, q, mass, strict=True):
        k = (o, rank[t] * nq + a)
        sums[k] = sums.get(k, 0.0) + m
        code[k] = t * nq + a
    keys = sorted(sums)
    n_obs = max(obs) + 1
    total = [math.fsum(sums[k] for k in keys if k[0] == o) for o in range(n_obs)]
    hashes = [sum(mixed(code[k]) for k in keys if k[0] == o) & MASK for o in range(n_obs)]
    return {"hobs": [k[0] for k in keys], "hcode": [code[k] for k in keys],
            "hmass": [sums[k] for k in keys], "total": total,
            "weight": [sums[k] / total[k[0]] for k in keys],
            "count": [sum(1 for k in keys if k[0] == o) for o in range(n_obs)],
            "hash": hashes,
            "first": [min(s for s, b in zip(s_seq, obs, strict=True) if b == o)
                      for o in range(n_obs)]}


def level(rng: np.random.Generator, n: int, spread: int, halfway: bool = False
          ) -> tuple[np.ndarray, ...]:
    """Random rows of a level: each row's observation (every one present), times and
    automaton state, mass and place; with ``halfway`` each observation's masses are
    ``1``, ``2**-53`` and ``2**-106``-sized terms whose exact sums lie at or next to a
    point half-way between two floats (where the double-double sum is unsure)."""
    n_obs = max(n // 6, 1)
    obs = np.sort(np.concatenate([np.arange(n_obs), rng.integers(0, n_obs, n - n_obs)]))
    tid = rng.integers(0, spread, n)
    q = rng.integers(0, 3, n)
    if halfway:
        mass = rng.choice(np.array([1.0, 2.0**-53, 2.0**-54, 2.0**-106, 3 * 2.0**-107,
                                    0.5, 2.0**-60]), n)
    else:
        mass = rng.random(n) * 10.0 ** rng.integers(-12, 1, n)
    s_seq = rng.permutation(n).astype(np.int64)
    return obs.astype(np.int64), tid, q, mass, s_seq


@pytest.mark.parametrize("halfway", [False, True])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_level_hypotheses_as_written_by_hand(seed: int, halfway: bool) -> None:
    rng = np.random.default_rng(seed)
    obs, tid, q, mass, s_seq = level(rng, 4000, 3 if halfway else 40, halfway)
    perm = np.argsort(obs, kind="stable").astype(np.int64)
    rng.shuffle(perm[: len(perm) // 2])  # any order of the rows within their groups
    perm = perm[np.argsort(obs[perm], kind="stable")]
    rank = rng.permutation(int(tid.max()) + 1).astype(np.int64)
    nq = 3
    n_obs = int(obs.max()) + 1
    got = gk.level_hypotheses(perm, obs, n_obs, tid, q, mass, s_seq, rank, np.int64(nq),
                              np.full((0, 0), -2, np.int64), np.zeros(n_obs, np.int64))
    hfirst, hobs, hcode, hmass, weight, total, count, hashes, first, _, _ = got
    want = by_hand(obs.tolist(), tid.tolist(), q.tolist(), mass.tolist(),
                   s_seq.tolist(), rank.tolist(), nq)
    assert hobs.tolist() == want["hobs"]
    assert hcode.tolist() == want["hcode"]
    assert (tid[hfirst] * nq + q[hfirst]).tolist() == want["hcode"]  # a row of each
    assert hmass.tolist() == want["hmass"]
    assert total.tolist() == want["total"]  # to the bit: math.fsum's
    assert weight.tolist() == want["weight"]
    assert count.tolist() == want["count"]
    assert [int(h) for h in hashes] == want["hash"]
    assert first.tolist() == want["first"]


def test_sums_half_way_are_math_fsum() -> None:
    """Sums whose exact value is a float and a half ulp away, or next to it: the kernel's
    total is math.fsum's where the double-double one would round the wrong way."""
    cases = [[1.0, 2.0**-53, 2.0**-106], [1.0, 2.0**-53, -0.0 + 2.0**-200],
             [1.0, 2.0**-53], [2.0, 2.0**-52, 2.0**-105, 2.0**-160],
             [1.0, 2.0**-54, 2.0**-54, 2.0**-107], [0.5] * 7 + [2.0**-54] * 3]
    for terms in cases:
        n = len(terms)
        z = np.zeros(n, np.int64)
        got = gk.level_hypotheses(np.arange(n, dtype=np.int64), z, 1,
                                  np.arange(n, dtype=np.int64), z,
                                  np.array(terms), np.arange(n, dtype=np.int64),
                                  np.arange(n, dtype=np.int64), np.int64(1),
                                  np.full((0, 0), -2, np.int64), np.zeros(1, np.int64))
        assert got[5][0] == math.fsum(terms), terms


@pytest.mark.parametrize("seed", [0, 1])
def test_observation_words_group_as_tuples(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 3000
    c = np.sort(rng.integers(0, n // 30, n))
    w2, occ, new = rng.integers(0, 50, n), rng.integers(0, 4, n), rng.integers(0, 8, n)
    obs, first, perm = gk.by_observation_bits(c, w2, occ, new, 2, 3)
    keys = list(zip(c.tolist(), w2.tolist(), occ.tolist(), new.tolist(), strict=True))
    rank = {k: i for i, k in enumerate(sorted(set(keys)))}
    assert obs.tolist() == [rank[k] for k in keys]
    assert [keys[i] for i in first.tolist()] == sorted(set(keys))
    assert np.all(np.diff(obs[perm]) >= 0)
    assert gk.by_observation_bits(c[::-1].copy(), w2, occ, new, 2, 3) is None


def random_case(seed: int, alarms: bool = True):
    """A small random sensed case of the bus grid: one or two cameras, their detection,
    delay and (with ``alarms``) false alarms drawn, a coarse epsilon."""
    rng = np.random.default_rng(seed)
    sensors = {}
    for event in rng.permutation(["b1", "b2"])[: int(rng.integers(1, 3))].tolist():
        fa = float(rng.choice([0.0, 0.1])) if alarms and not sensors else 0.0
        sensors[event] = Sensor(float(rng.choice([0.4, 0.6, 0.8])),
                                delay=int(rng.integers(0, 2)) if fa == 0.0 else 0,
                                false_alarm=fa)
    return with_sensors("bus_grid.toml", sensors, float(rng.choice([0.2, 0.3])))


def build(model, merge: bool):
    return belief_product(model.game, to_dta(model.spec), model.distributions,
                          dict(model.sensors), model.epsilon, max_states=10**6,
                          late_reports=False, merge=merge)


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_random_cases_equal_one_state_at_a_time(seed: int) -> None:
    """Every level by the kernels (forced on, the cases being small): the states, their
    order, posteriors, transitions and moves of the build one state at a time (which
    keeps no report counts: no false alarms here)."""
    model = random_case(seed, alarms=False)
    with rows.running_kernels(True):
        belief = build(model, merge=False)
    assert_same(belief, reference(model, belief))


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_random_cases_merged_equal_the_numpy_lines(seed: int) -> None:
    """With the merge (shifted times, canonical report counts): the kernels' product is
    the NumPy lines', to the bit."""
    model = random_case(seed)
    with rows.running_kernels(False):
        plain = build(model, merge=True)
    with rows.running_kernels(True):
        fast = build(model, merge=True)
    a, b = fast.mdp, plain.mdp
    for x, y in ((a.matrix.data, b.matrix.data), (a.matrix.indices, b.matrix.indices),
                 (a.matrix.indptr, b.matrix.indptr), (a.row_groups, b.row_groups),
                 (a.choice_actions, b.choice_actions)):
        assert np.array_equal(x, y)
    assert a.states == b.states
    assert list(fast.moves) == list(plain.moves)


def test_end_sums_as_sorted_by_hand() -> None:
    """Rows ending in a record, from three lists each in the loops' order: merged as a
    stable sort of their keys would, grouped by (choice, record) in ascending order,
    each group's mass summed in that order with Python floats, its first row's place;
    a list out of order: refused (the caller sorts)."""
    rng = np.random.default_rng(7)
    lists = []
    for width in (2, 3, 4):  # (c, o), (c, o, b), (c, o, b, s) drawn, the rest -1
        keys = sorted({tuple(rng.integers(0, 6, width).tolist()) for _ in range(300)})
        lists.append([k + (-1,) * (4 - width) + (int(rng.integers(0, 4)),
                                                 float(rng.random()) * 10.0 ** -int(
                                                     rng.integers(0, 9)))
                      for k in keys])
    rows_ = [r for lst in lists for r in lst]
    cols = [np.array([r[j] for r in rows_], np.int64) for j in range(5)]
    mass = np.array([r[5] for r in rows_])
    starts = np.cumsum([0] + [len(x) for x in lists]).astype(np.int64)
    ok, g_c, g_r, g_m, g_p = gk.end_sums(*cols, mass, starts)
    assert ok
    merged = sorted(range(len(rows_)), key=lambda i: rows_[i][:4])  # stable
    want: dict[tuple[int, int], list] = {}
    for p, i in enumerate(merged):
        k = (rows_[i][0], rows_[i][4])
        if k not in want:
            want[k] = [0.0, p]
        want[k][0] += rows_[i][5]
    keys = sorted(want)
    assert list(zip(g_c.tolist(), g_r.tolist(), strict=True)) == keys
    assert g_m.tolist() == [want[k][0] for k in keys]
    assert g_p.tolist() == [want[k][1] for k in keys]
    backwards = [x.copy() for x in cols]
    backwards[0][: starts[1]] = backwards[0][: starts[1]][::-1]
    assert not gk.end_sums(*backwards, mass, starts)[0]


def test_decided_alone_by_hand() -> None:
    """The decided rows' observations that no undecided group has, in order, each with
    its one record or -1 where its rows disagree: against sets and dictionaries."""
    rng = np.random.default_rng(8)
    n = 2000
    c = np.sort(rng.integers(0, 60, n))
    w2, occ, new = rng.integers(0, 9, n), rng.integers(0, 2, n), rng.integers(0, 4, n)
    end = rng.integers(0, 3, n)
    undecided = sorted({(int(rng.integers(0, 60)), int(rng.integers(0, 9)),
                         int(rng.integers(0, 2)), int(rng.integers(0, 4)))
                        for _ in range(800)})
    g = [np.array(x, np.int64) for x in zip(*undecided, strict=True)]
    pick, one = gk.decided_alone(c, w2, occ, new, end, *g, np.int64(1), np.int64(2))
    records: dict[tuple[int, ...], set[int]] = {}
    for row in zip(c.tolist(), w2.tolist(), occ.tolist(), new.tolist(), end.tolist(),
                   strict=True):
        records.setdefault(row[:4], set()).add(row[4])
    alone = sorted(k for k in records if k not in set(undecided))
    assert [(int(c[i]), int(w2[i]), int(occ[i]), int(new[i])) for i in pick] == alone
    assert one.tolist() == [min(records[k]) if len(records[k]) == 1 else -1 for k in alone]
