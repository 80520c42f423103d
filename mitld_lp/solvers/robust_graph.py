"""Graph analyses of a robust game: the robot picks a choice, nature one of the choice's
vertex distributions (:mod:`mitld_lp.product.imdp`).  An outcome whose probability is 0 at some
end of a hazard band is missing from that vertex row, so every analysis here sees the
graphs nature can make, not the nominal one.

* :func:`positive_attractor`: where the robot can make the target's probability positive
  against every nature: ``mu Y. T | {s : exists c, forall v: supp(v) meets Y}``.  Its
  complement is where the robust value is 0 (``prob0``).
* :func:`almost_sure`: where the robot reaches the target with probability 1 against every
  nature: ``nu X. mu Y. T | {s : exists c, forall v: supp(v) in X and supp(v) meets Y}``.
* :func:`keeping`: where the robot can keep every run inside a set for ever against every
  nature: ``nu X. K & {s : exists c, forall v: supp(v) in X}`` (robust acceptance of a
  safety part, ``K`` the persistent states).
* :func:`end_components`: the maximal end components when nature is held to a subset of
  its rows (the rows optimal for the current lower bound, for deflating the upper bound).
* :func:`levels`: the strongly connected blocks of the support graph, downstream first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from mitld_lp.mdp import MDPShape
from mitld_lp.product.imdp import IntervalMDP, vertex_rows
from mitld_lp.util.traversal import strong_components

__all__ = ["RobustGame", "almost_sure", "cooperative", "end_components", "gather", "keeping",
           "levels", "positive_attractor", "robust_game", "take_rows"]


@dataclass(frozen=True, slots=True, eq=False)
class RobustGame(MDPShape):
    """The arrays a robust solver reads: state ``s``'s choices are
    ``row_groups[s]:row_groups[s+1]``, choice ``c``'s vertex rows
    ``vertex_groups[c]:vertex_groups[c+1]`` of ``matrix`` (``(n_rows, n_states)`` CSR,
    each row a distribution).  A plain MDP is the game with one row per choice."""

    matrix: sp.csr_array
    vertex_groups: np.ndarray
    row_groups: np.ndarray

    @property
    def n_rows(self) -> int:
        return int(self.vertex_groups[-1])

    def distributions(self) -> tuple[sp.csr_array, np.ndarray | None]:
        """Nature's vertex rows, several per choice (its :class:`~mitld_lp.mdp.MDPShape`)."""
        return self.matrix, self.vertex_groups

    def row_choice(self) -> np.ndarray:
        return np.repeat(np.arange(self.n_choices), np.diff(self.vertex_groups))

    def row_state(self) -> np.ndarray:
        return self.choice_state()[self.row_choice()]

    def restrict(self, policy: np.ndarray) -> RobustGame:
        """The game in which state ``s`` has the one choice ``policy[s]``."""
        starts = self.vertex_groups[policy]
        stops = self.vertex_groups[policy + 1]
        rows = gather(starts, stops)
        groups = np.zeros(policy.size + 1, dtype=np.int64)
        np.cumsum(stops - starts, out=groups[1:])
        return RobustGame(take_rows(self.matrix, rows, self.n_states), groups,
                          np.arange(policy.size + 1, dtype=np.int64))


def gather(starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    """The indices ``starts[i]:stops[i]`` for every ``i``, concatenated."""
    lengths = (stops - starts).astype(np.int64)
    if lengths.sum() == 0:
        return np.zeros(0, dtype=np.int64)
    ends = np.cumsum(lengths)
    offsets = np.repeat(starts - (ends - lengths), lengths)
    return np.arange(int(ends[-1]), dtype=np.int64) + offsets


def take_rows(m: sp.csr_array, rows: np.ndarray, n_cols: int) -> sp.csr_array:
    """The rows ``rows`` of ``m`` (``n_cols`` columns), in that order."""
    at = gather(m.indptr[rows], m.indptr[rows + 1])
    indptr = np.zeros(rows.size + 1, dtype=np.int64)
    np.cumsum(np.diff(m.indptr)[rows], out=indptr[1:])
    return sp.csr_array((m.data[at], m.indices[at], indptr), shape=(rows.size, n_cols))


def _segment_all(flags: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Per group ``groups[i]:groups[i+1]`` (never empty): whether every flag is set."""
    return np.minimum.reduceat(flags.astype(np.int8), groups[:-1]).astype(bool)


def _segment_any(flags: np.ndarray, groups: np.ndarray) -> np.ndarray:
    return np.maximum.reduceat(flags.astype(np.int8), groups[:-1]).astype(bool)


def positive_attractor(
    game: RobustGame,
    target: np.ndarray,
    *,
    allowed: np.ndarray | None = None,
    inside: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(Y, via)``: the least ``Y`` containing ``target`` and every state ``s`` (in
    ``inside``) with a choice ``c`` (in ``allowed``) all of whose vertex rows reach into
    ``Y``; ``via[s]`` is the choice that put ``s`` in (-1 for the target and outside).
    Computed backward from the target, each row looked at once."""
    n = game.n_states
    allowed = np.ones(game.n_choices, bool) if allowed is None else allowed
    inside = np.ones(n, bool) if inside is None else inside
    back = sp.csr_array(game.matrix.T)  # state -> the rows that reach it
    row_choice = game.row_choice()
    choice_state = game.choice_state()
    need = np.diff(game.vertex_groups)
    count = np.zeros(game.n_choices, dtype=np.int64)
    hit = np.zeros(game.n_rows, dtype=bool)
    y = np.asarray(target, dtype=bool).copy()
    via = np.full(n, -1, dtype=np.int64)
    frontier = np.flatnonzero(y)
    while frontier.size:
        rows = back.indices[gather(back.indptr[frontier], back.indptr[frontier + 1])]
        rows = np.unique(rows)
        rows = rows[~hit[rows]]
        if rows.size == 0:
            break
        hit[rows] = True
        np.add.at(count, row_choice[rows], 1)
        cands = np.unique(row_choice[rows])
        full = cands[(count[cands] == need[cands]) & allowed[cands]]
        states = choice_state[full]
        fresh = ~y[states] & inside[states]
        full, states = full[fresh], states[fresh]
        states, first = np.unique(states, return_index=True)
        y[states] = True
        via[states] = full[first]
        frontier = states
    return y, via


def _rows_inside(game: RobustGame, mask: np.ndarray) -> np.ndarray:
    """Per vertex row: whether its whole support lies in ``mask``."""
    out = np.ones(game.n_rows, dtype=bool)
    lengths = np.diff(game.matrix.indptr)
    nonempty = lengths > 0
    if nonempty.any():
        ok = mask[game.matrix.indices].astype(np.int8)
        starts = game.matrix.indptr[:-1][nonempty]
        out[nonempty] = np.minimum.reduceat(ok, starts).astype(bool)
    return out


def almost_sure(game: RobustGame, target: np.ndarray, positive: np.ndarray) -> np.ndarray:
    """The states where the robot reaches ``target`` with probability 1 against every
    nature (module docstring); ``positive``: the positive attractor, where it starts."""
    x = positive.copy()
    while True:
        stay = _segment_all(_rows_inside(game, x), game.vertex_groups)
        y, _ = positive_attractor(game, target, allowed=stay, inside=x)
        if np.array_equal(y, x):
            return x
        x = y


def keeping(game: RobustGame, inside: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(W, stay)``: the greatest ``W`` within ``inside`` whose every state has a choice
    all of whose vertex rows keep their whole support in ``W`` (module docstring); from
    ``W`` the robot keeps every run in ``W`` for ever, whatever law of the bands nature
    plays, by ``stay[s]`` (the first such choice; -1 outside ``W``)."""
    x = np.asarray(inside, dtype=bool).copy()
    choice_state = game.choice_state()
    while True:
        ok = _segment_all(_rows_inside(game, x), game.vertex_groups) & x[choice_state]
        nxt = np.zeros_like(x)
        nxt[choice_state[ok]] = True
        if np.array_equal(nxt, x):
            break
        x = nxt
    stay = np.full(game.n_states, -1, dtype=np.int64)
    good = np.flatnonzero(ok)
    states, first = np.unique(choice_state[good], return_index=True)
    stay[states] = good[first]
    return x, stay


def end_components(
    game: RobustGame, inside: np.ndarray, rows_allowed: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(label, staying)``: the maximal end components within ``inside`` when nature may
    use only the rows in ``rows_allowed``: sets ``X`` where every state has a choice one
    of whose allowed rows keeps the play in ``X``, strongly connected through such rows.
    ``label[s]`` numbers them (-1: in none); ``staying[c]``: choice ``c`` has an allowed
    row whose support lies in its state's component."""
    n = game.n_states
    row_state = game.row_state()
    label = np.where(inside, 0, -1).astype(np.int64)
    while True:
        # a row stays when allowed and its support lies in its state's component
        ok = rows_allowed & (label[row_state] >= 0)
        ok &= _same_label(game, label, row_state)
        staying = _segment_any(ok, game.vertex_groups)
        alive = _segment_any(staying, game.row_groups) & (label >= 0)
        rows = np.flatnonzero(ok & alive[row_state])
        r_of = np.repeat(rows, np.diff(game.matrix.indptr)[rows])
        cols = game.matrix.indices[gather(game.matrix.indptr[rows], game.matrix.indptr[rows + 1])]
        graph = sp.csr_array((np.ones(cols.size), (row_state[r_of], cols)), shape=(n, n))
        _, comp = strong_components(graph)
        new = np.where(alive, comp, -1)
        if _same_partition(new, label):
            return new, staying & (new[game.choice_state()] >= 0)
        label = new


def _same_label(game: RobustGame, label: np.ndarray, row_state: np.ndarray) -> np.ndarray:
    entry_row = np.repeat(np.arange(game.n_rows), np.diff(game.matrix.indptr))
    same = (label[game.matrix.indices] == label[row_state[entry_row]]).astype(np.int8)
    out = np.ones(game.n_rows, dtype=bool)
    lengths = np.diff(game.matrix.indptr)
    nz = lengths > 0
    out[nz] = np.minimum.reduceat(same, game.matrix.indptr[:-1][nz]).astype(bool)
    return out


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    if not np.array_equal(a >= 0, b >= 0):
        return False
    live = a >= 0
    if not live.any():
        return True
    pairs = np.unique(np.stack([a[live], b[live]]), axis=1)
    return pairs.shape[1] == np.unique(a[live]).size == np.unique(b[live]).size


def levels(game: RobustGame, states: np.ndarray) -> list[np.ndarray]:
    """The strongly connected blocks of the support graph on ``states`` (a bool mask),
    grouped in levels, downstream first: a block's successors outside it are all in
    earlier levels (or outside ``states``).  Each level is an array of state ids."""
    n = game.n_states
    row_state = game.row_state()
    entry_row = np.repeat(np.arange(game.n_rows), np.diff(game.matrix.indptr))
    src, dst = row_state[entry_row], game.matrix.indices
    keep = states[src] & states[dst]
    graph = sp.csr_array((np.ones(int(keep.sum())), (src[keep], dst[keep])), shape=(n, n))
    n_comp, comp = strong_components(graph)
    cs, cd = comp[src[keep]], comp[dst[keep]]
    pairs = np.unique(cs[cs != cd] * n_comp + cd[cs != cd])
    cs, cd = pairs // n_comp, pairs % n_comp
    # reversed: from a block to its predecessors
    dag = sp.csr_array((np.ones(pairs.size), (cd, cs)), shape=(n_comp, n_comp))
    out_degree = np.bincount(cs, minlength=n_comp)
    # the blocks of states outside the mask are singletons nobody waits for
    used = np.zeros(n_comp, dtype=bool)
    used[comp[states]] = True
    ready = np.flatnonzero((out_degree == 0) & used)
    order = np.argsort(comp, kind="stable")
    starts = np.searchsorted(comp[order], np.arange(n_comp + 1))
    result = []
    while ready.size:
        members = order[gather(starts[ready], starts[ready + 1])]
        result.append(members[states[members]])
        preds = dag.indices[gather(dag.indptr[ready], dag.indptr[ready + 1])]
        np.subtract.at(out_degree, preds, 1)
        preds = np.unique(preds)
        ready = preds[(out_degree[preds] == 0) & used[preds]]
    return result


def robust_game(imdp: IntervalMDP) -> RobustGame:
    """The robust game of ``imdp``: nature's rows are the vertex distributions."""
    v = vertex_rows(imdp)
    return RobustGame(v.matrix, v.groups, imdp.row_groups)


def cooperative(game: RobustGame) -> RobustGame:
    """``game`` with nature on the robot's side (the bands read for their best law):
    every vertex row is a choice of its own, so ``max_c min_rows`` of the result is
    ``max_c max_v`` of ``game`` (the best law of a box of hazards is at a vertex too:
    the value of a step is multilinear in the hazards).  Choice ``k`` of the result is
    row ``k`` of ``game``: ``game.row_choice()`` maps it back to the robot's choice."""
    n_rows = game.n_rows
    return RobustGame(game.matrix, np.arange(n_rows + 1, dtype=np.int64),
                      np.asarray(game.vertex_groups[game.row_groups], dtype=np.int64))
