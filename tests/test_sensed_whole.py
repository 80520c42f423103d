"""The hypothesis kernel that groups each choice's rows by observation as it makes them
(:func:`mitld_lp.sensing.kernels.hypothesis_rows` with :func:`~mitld_lp.sensing.
group_kernels.group_run`), writing a level's rows into pages kept from the last level,
the build run with NumPy's huge-page advice off (:func:`mitld_lp.sensing.rows.
small_pages`), against answers found another way: each level's grouping against the
rows' observations sorted as Python tuples; whole products of small random cases against
the one-state-at-a-time build of tests/test_sensing_build.py, and against the previous
path (the rows grouped after the kernel) and the NumPy lines by a digest of every bit."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from test_sensed_build import build, random_case
from test_sensing_build import assert_same, reference

from mitld_lp.sensing import compiled, rows

pytest.importorskip("numba")


def digest(belief) -> str:
    """A SHA-256 of the product's matrix (every probability's bits, columns, rows), its
    states' choices and actions (experiments/bench_sensed.py's)."""
    h = hashlib.sha256()
    m = belief.mdp.matrix
    for x in (m.data, m.indices, m.indptr, belief.mdp.row_groups, belief.mdp.choice_actions):
        h.update(np.ascontiguousarray(x).tobytes())
    return h.hexdigest()


def spied(monkeypatch) -> list[tuple[np.ndarray, ...]]:
    """Each level's undecided rows ``(c, w2, occ, new)`` and the kernel's grouping of
    them (None where it gave none), as :func:`compiled.observations` receives them."""
    seen: list[tuple[np.ndarray, ...]] = []
    observations = compiled.observations

    def spy(fb, c, w2, occ, new, done=None):
        seen.append((c.copy(), w2.copy(), occ.copy(), new.copy(),
                     None if done is None else tuple(x.copy() for x in done)))
        return observations(fb, c, w2, occ, new, done)

    monkeypatch.setattr(compiled, "observations", spy)
    return seen


def check_grouping(c, w2, occ, new, done) -> None:
    """The kernel's grouping as Python tuples give it: each row's group its
    observation's place among the distinct observations sorted, one row of each
    carrying its observation, the rows in their groups' order and, within a group, in
    their own."""
    obs, first, perm = done
    keys = list(zip(c.tolist(), w2.tolist(), occ.tolist(), new.tolist(), strict=True))
    distinct = sorted(set(keys))
    place = {k: i for i, k in enumerate(distinct)}
    assert obs.tolist() == [place[k] for k in keys]
    assert [keys[i] for i in first.tolist()] == distinct
    assert perm.tolist() == sorted(range(len(keys)), key=lambda i: (place[keys[i]], i))


@pytest.mark.parametrize("seed", [3, 4, 5, 6])
def test_grouped_levels_and_states_as_one_state_at_a_time(monkeypatch, seed: int) -> None:
    """Every level by the kernels (forced on, the cases being small), each grouped by
    the hypothesis kernel: its groups those of sorted Python tuples, and the product's
    states, their order, posteriors, transitions and moves those of the build one state
    at a time (no merge, no false alarms: what that build keeps)."""
    model = random_case(seed, alarms=False)
    seen = spied(monkeypatch)
    with rows.running_kernels(True):
        belief = build(model, merge=False)
    grouped = [s for s in seen if s[4] is not None]
    assert grouped and len(grouped) == sum(1 for s in seen if len(s[0]))
    for c, w2, occ, new, done in grouped:
        check_grouping(c, w2, occ, new, done)
    assert_same(belief, reference(model, belief))


@pytest.mark.parametrize("seed", [3, 4, 5, 6, 7])
def test_digests_equal_the_previous_path_and_numpy(monkeypatch, seed: int) -> None:
    """With the merge and false alarms drawn: the product grouped in the kernel is, to
    the bit, the one grouped after it (the previous path) and the NumPy lines' one."""
    model = random_case(seed)
    with rows.running_kernels(False):
        plain = build(model, merge=True)
    with rows.running_kernels(True):
        fast = build(model, merge=True)
        monkeypatch.setattr(compiled, "GROUPED", False)
        before = build(model, merge=True)
    assert digest(fast) == digest(before) == digest(plain)
    assert fast.mdp.states == before.mdp.states == plain.mdp.states
    assert list(fast.moves) == list(plain.moves)


def test_rows_made_by_kernel_stay_whole_across_levels(monkeypatch) -> None:
    """The pages a level's rows are written to are kept for the next: a build whose
    work arrays start too small for any level (each one made anew, larger) and one that
    starts with them far larger than needed give the same product."""
    from mitld_lp.sensing import frontier

    model = random_case(5)
    init = frontier.FrontierBuilder.__init__
    digests = []
    for size in (0, 1 << 16):
        def start(self, *args, size=size, **kwargs):
            init(self, *args, **kwargs)
            self.row_work = (np.full((19, size), -7, np.int64), np.full((2, size), np.nan))

        monkeypatch.setattr(frontier.FrontierBuilder, "__init__", start)
        with rows.running_kernels(True):
            digests.append(digest(build(model, merge=True)))
    assert digests[0] == digests[1]


def test_small_pages_restores_numpy_advice() -> None:
    """Within :func:`rows.small_pages` NumPy's huge-page advice is off; after it (also
    after an error inside) it is what it was."""
    switch = pytest.importorskip("numpy._core.multiarray")._set_madvise_hugepage
    original = switch(True)
    try:
        for was in (True, False):
            switch(was)
            with rows.small_pages():
                assert switch(False) is False  # the setting inside: off
            assert switch(was) is was
            with pytest.raises(KeyError), rows.small_pages():
                raise KeyError("inside")
            assert switch(True) is was
    finally:
        switch(original)
