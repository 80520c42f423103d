"""The product construction as it was written first: one state at a time, in Python.

Kept as the peer of ``experiments/bench_product.py`` (the speed-up is measured against it
in the same run) and as an independent reference in the tests (the array construction of
:func:`mitld_lp.product.product` must give the same MDP, state for state and bit for
bit).  Not used by the library.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any, cast

import numpy as np
import scipy.sparse as sp

from mitld_lp import defaults
from mitld_lp.automata.sta import STA, TRUNCATED
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing, ProductState, ProductTooLarge
from mitld_lp.worlds.game import Game


def reference_product(
    game: Game[Any],
    sta: STA,
    *,
    max_states: int = defaults.MAX_STATES,
) -> MDP:
    """The reachable product MDP of ``game`` and ``sta``, breadth first, one state at
    a time (the semantics of :mod:`mitld_lp.product`)."""
    dta = sta.dta
    accepting, rejecting = dta.accepting, dta.rejecting
    # Hot loop: states are plain tuples ``(s, q, pending, clock)`` here (hashing a tuple
    # is much cheaper than building a frozen record per transition); the records are
    # made once at the end.  Absorbing states are :class:`Absorbing` members.
    index: dict[Hashable, int] = {}
    states: list[Hashable] = []

    def intern(key: Hashable) -> int:
        i = index.get(key)
        if i is None:
            i = index[key] = len(states)
            states.append(key)
            if len(states) > max_states:
                raise ProductTooLarge(
                    f"the product has more than {max_states:,} reachable states "
                    f"(automaton: {dta.n_states} states, events: {sorted(sta.events)}, "
                    f"truncation points: {sta.truncation_points or 'none'}); raise "
                    "max_states, loosen epsilon, or shrink the model"
                )
        return i

    s0 = game.initial
    q0 = dta.step(dta.initial, game.propositions(s0))
    first = (
        Absorbing.TARGET if q0 == accepting
        else Absorbing.SINK if q0 == rejecting
        else (s0, q0, sta.events, 0)
    )
    initial = intern(first)

    label_cache: dict[tuple[Hashable, frozenset[str]], frozenset[str]] = {}
    succ_cache: dict[tuple[Hashable, str, frozenset[str]], tuple] = {}
    step_cache: dict[tuple[int, frozenset[str]], Hashable] = {}
    action_index: dict[str, int] = {}

    indptr = [0]
    cols: list[int] = []
    vals: list[float] = []
    row_groups = [0]
    choice_actions: list[int] = []

    head = 0
    while head < len(states):
        key = states[head]
        head += 1
        if isinstance(key, str):
            cols.append(head - 1)
            vals.append(1.0)
            indptr.append(len(cols))
            choice_actions.append(ABSORB)
            row_groups.append(len(choice_actions))
            continue
        s, q, pending, clock = key  # type: ignore[misc]
        outcomes = sta.outcomes(pending, clock)
        for action in game.actions(s):
            row: dict[int, float] = {}
            for out in outcomes:
                po = out.probability
                if out.clock == TRUNCATED:
                    j = intern(Absorbing.TRUNCATED)
                    row[j] = row.get(j, 0.0) + po
                    continue
                occurred, left, clock2 = out.occurred, out.pending, out.clock
                skey = (s, action, occurred)
                succ = succ_cache.get(skey)
                if succ is None:
                    succ = succ_cache[skey] = tuple(game.successors(s, action, occurred))
                for s2, p in succ:
                    lkey = (s2, occurred)
                    label = label_cache.get(lkey)
                    if label is None:
                        label = label_cache[lkey] = game.propositions(s2) | occurred
                    dkey = (q, label)
                    q2 = step_cache.get(dkey)
                    if q2 is None:
                        q2 = dta.step(q, label)
                        q2 = step_cache[dkey] = (
                            Absorbing.TARGET if q2 == accepting
                            else Absorbing.SINK if q2 == rejecting
                            else q2
                        )
                    nkey = q2 if isinstance(q2, str) else (s2, q2, left, clock2)
                    j = index.get(nkey)
                    if j is None:
                        j = intern(nkey)
                    row[j] = row.get(j, 0.0) + po * p
            cols.extend(row)
            vals.extend(row.values())
            indptr.append(len(cols))
            a = action_index.get(action)
            if a is None:
                a = action_index[action] = len(action_index)
            choice_actions.append(a)
        row_groups.append(len(choice_actions))

    special = {Absorbing.TARGET: 1, Absorbing.SINK: 2, Absorbing.TRUNCATED: 3}
    kinds = [special[k] if isinstance(k, Absorbing) else 0 for k in states]
    records: list[Hashable] = [
        k if isinstance(k, str) else ProductState(*cast(tuple, k)) for k in states
    ]
    n = len(states)
    matrix = sp.csr_array(
        (np.asarray(vals, dtype=np.float64), np.asarray(cols, dtype=np.int32),
         np.asarray(indptr, dtype=np.int64)),
        shape=(len(choice_actions), n),
    )
    kind = np.asarray(kinds, dtype=np.int8)
    mdp = MDP(
        matrix=matrix,
        row_groups=np.asarray(row_groups, dtype=np.int64),
        choice_actions=np.asarray(choice_actions, dtype=np.int32),
        action_names=tuple(sorted(action_index, key=action_index.__getitem__)),
        initial=initial,
        target=kind == 1,
        sink=kind == 2,
        truncated=kind == 3,
        states=tuple(records),
    )
    return mdp
