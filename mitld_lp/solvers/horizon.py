"""Step-bounded reachability ``psi U[0,k] phi`` (``F[0,k] phi``) on an explored world,
by backward induction over its states: no product with a step counter.

    v_0 = [phi],  v_{j+1}(s) = 1 if phi(s), 0 if not psi(s),
                  else opt_c sum_t P_c(t) v_j(t)

``v_k`` at the initial state is ``Pmax`` (``opt = max``) or ``Pmin`` of the task (step 0
is the initial state, as PRISM's ``F<=k``).  Two vectors ``lo <= v_j <= hi`` are carried
as in :func:`mitld_lp.solvers.step_bounded.horizon_bracket`: each choice's float sum
bounded by its row's factors (:func:`mitld_lp.solvers.rounding.rounding`, the stored
probabilities within :data:`~mitld_lp.solvers.rounding.ETA` of the model's), moved one
float outward, the optimum over a state's choices of bounds a bound of the optimum; so
``lo_k <= v_k <= hi_k`` by induction.

Only the states whose value is read are computed: at step ``j`` (making ``v_{j+1}``)
a state whose backward distance to ``phi`` through ``psi``-states is past ``j + 1`` has
``v_{j+1} = 0`` exactly (both bounds keep their 0), and a state more than ``k - j - 1``
steps from the initial state is never read at ``v_{j+1}`` (it is read only by a state
one step nearer, at the next step).  The states in between are contiguous steps for
each state, so every value read was written at the step before or is that exact 0.
On resource-gathering 1300-100-100 this is 1.2% of the 1300 x 958,801 (step, state)
pairs (docs/results.md, horizon-78).

The policy: for a maximum, at ``j + 1`` steps left, the choice best for ``lo_j``; its
value is at least ``lo`` (``lo_{j+1}(s) = below(P_c lo_j) <= P_c lo_j <= P_c
v^pi_j``); for a minimum the choice best for ``hi_j``, its value at most ``hi``.  Kept
per step for the active states with more than one choice (the narrowest unsigned type),
only within :data:`POLICY_MAX_BYTES`, checked before the work; the work, ``k`` times
the transitions and choices (before pruning), within :data:`MAX_WORK`, checked before
it starts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mitld_lp.solvers.rounding import ETA, rounding
from mitld_lp.util.progress import bar as progress_bar
from mitld_lp.util.stops import TimeUp

__all__ = ["MAX_WORK", "POLICY_MAX_BYTES", "HorizonSolution", "HorizonTooLarge",
           "horizon_reach", "horizon_work", "policy_type"]

MAX_WORK = 40_000_000_000
"""The most work of the induction, steps times (transitions + choices): a step is one
pass over the world's undecided transitions, both bounds at once, about 1.5 ns a
transition on this machine (resource-gathering 1300-100-100: 1300 steps of a world of
958,894 states, docs/results.md, horizon-78), so this is about a minute."""

POLICY_MAX_BYTES = 256 * 2**20
"""The most memory the step-dependent policy may take (one row per step, one entry per
state with a choice, the narrowest unsigned type): past it the answer is the bracket
alone and the verbs that need the policy refuse, naming this budget."""


class HorizonTooLarge(ValueError):
    """The induction's work is past :data:`MAX_WORK` (checked before it starts)."""


@dataclass(frozen=True, slots=True, eq=False)
class HorizonSolution:
    """The bracket of ``v_k`` (``lo``, ``hi``; exact at the initial state's bound, and at
    every state that :attr:`active` at the last step), the steps, the sense, and the
    policy: ``picks[offsets[j]:offsets[j + 1]]`` the local choices at step ``j`` (``j +
    1`` steps left) of the active states with a choice, in the order of ``order``;
    ``picks`` None when it was not kept, ``why_no_policy`` then saying why."""

    lo: np.ndarray
    hi: np.ndarray
    steps: int
    sense: str
    order: np.ndarray  # the undecided states ever active, by backward distance
    back: np.ndarray  # per state: steps to the goal (-1: never), through allowed states
    ahead: np.ndarray  # per state: steps from the initial state (-1: never)
    multi: np.ndarray  # per state: more than one choice
    picks: np.ndarray | None
    offsets: np.ndarray
    why_no_policy: str
    seconds: float

    def active(self, step: int) -> np.ndarray:
        """The states whose value the induction computes at step ``step`` (``step + 1``
        steps left), in its order."""
        head = self.order[:int(np.searchsorted(self.back[self.order], step + 1, "right"))]
        return head[self.ahead[head] <= self.steps - step - 1]

    def decisions(self, step: int) -> tuple[np.ndarray, np.ndarray]:
        """``(states, local choices)`` of the policy at step ``step`` (``step + 1`` steps
        left): the active states with a choice (any choice is as good elsewhere: the value
        there is 0, or the state is never reached with so many steps left)."""
        if self.picks is None:
            raise ValueError(f"no policy kept: {self.why_no_policy}")
        states = self.active(step)
        states = states[self.multi[states]]
        return states, self.picks[self.offsets[step]:self.offsets[step + 1]]

    def choice(self, state: int, steps_left: int) -> int | None:
        """The policy's local choice index at ``state`` with ``steps_left`` steps left
        (None without a policy or steps)."""
        if self.picks is None or steps_left <= 0 or steps_left > self.steps:
            return None
        states, picks = self.decisions(steps_left - 1)
        at = np.flatnonzero(states == state)
        return int(picks[at[0]]) if at.size else 0


def horizon_work(choices: np.ndarray, branches: np.ndarray, steps: int) -> int:
    """The induction's work before pruning: ``steps`` times the world's transitions and
    choices (the bound checked; the pruned work is what the search finds active)."""
    return steps * (int(branches[-1]) + int(choices[-1]))


def policy_type(choices: np.ndarray) -> np.dtype:
    """The narrowest unsigned type of a state's local choice index."""
    widest = int(np.diff(choices).max(initial=1))
    return np.dtype(np.uint8 if widest <= 256 else np.uint16 if widest <= 65536
                    else np.uint32)


def horizon_reach(choices: np.ndarray, branches: np.ndarray, targets: np.ndarray,
                  probabilities: np.ndarray, goal: np.ndarray, allowed: np.ndarray,
                  steps: int, sense: str = "max", *, initial: int = 0, eta: float = ETA,
                  max_work: int = MAX_WORK, policy_max_bytes: int = POLICY_MAX_BYTES,
                  time_limit: float | None = None, progress: bool | None = None
                  ) -> HorizonSolution:
    """The bracket of ``allowed U[0,steps] goal`` at ``initial`` (and every state it
    needs), in the world given by its arrays (:class:`mitld_lp.worlds.table.WorldTable`'s
    ``choices``, ``branches``, ``targets``, ``probabilities``), optimised in ``sense``
    (module docs).  ``goal`` and ``allowed``: a bool per state.  Raises
    :class:`HorizonTooLarge` past ``max_work`` (before any work), :class:`TimeUp` past
    ``time_limit`` seconds.  ``progress``: a bar over the steps (:mod:`mitld_lp.util.progress`)."""
    import scipy.sparse as sp

    from mitld_lp.solvers.horizon_kernels import distances, reach_steps

    if sense not in ("max", "min") or steps < 0:
        raise ValueError(f"sense {sense!r} / steps {steps!r}")
    work = horizon_work(choices, branches, steps)
    if work > max_work:
        raise HorizonTooLarge(
            f"step-bounded reachability: {steps:,} steps x ({int(branches[-1]):,} "
            f"transitions + {int(choices[-1]):,} choices) = {work:,} updates, more than "
            f"the {max_work:,} of mitld_lp.solvers.horizon.MAX_WORK")
    t0 = time.perf_counter()
    deadline = t0 + (np.inf if time_limit is None else time_limit)
    n = choices.size - 1
    goal, allowed = np.asarray(goal, dtype=bool), np.asarray(allowed, dtype=bool)
    moving = allowed & ~goal
    arrays = (np.asarray(choices, dtype=np.int64), np.asarray(branches, dtype=np.int64),
              np.asarray(targets, dtype=np.int64))
    back = distances(n, np.flatnonzero(goal), moving, *arrays, True)
    ahead = distances(n, np.array([initial]), moving, *arrays, False)
    live = np.flatnonzero(moving & (back >= 0) & (ahead >= 0) & (back + ahead <= steps))
    order = live[np.argsort(back[live], kind="stable")]
    ends = np.searchsorted(back[order], np.arange(1, steps + 1), "right")
    multi = np.diff(choices) > 1
    # per step, the active states with a choice: from step back - 1 to steps - ahead - 1
    kept = order[multi[order]]
    runs = np.zeros(steps + 1, dtype=np.int64)
    np.add.at(runs, back[kept] - 1, 1)
    np.add.at(runs, steps - ahead[kept], -1)
    offsets = np.concatenate(([0], np.cumsum(np.cumsum(runs)[:steps])))
    dtype = policy_type(choices)
    size = int(offsets[-1]) * dtype.itemsize
    why = ""
    if size > policy_max_bytes:
        why = (f"the step-dependent policy ({int(offsets[-1]):,} decisions of states with "
               f"a choice over {steps:,} steps x {dtype.itemsize} byte(s) = {size:,} "
               f"bytes) is past the {policy_max_bytes:,} bytes allowed "
               "(mitld_lp.solvers.horizon.POLICY_MAX_BYTES, at most half of max_memory)")
        picks = np.zeros(0, dtype=np.uint8)
    else:
        picks = np.zeros(int(offsets[-1]), dtype=dtype)
    matrix = sp.csr_array((probabilities, targets, branches), shape=(choices[-1], n))
    r = rounding(matrix, eta)
    lo = goal.astype(np.float64)
    hi, lo2, hi2 = lo.copy(), lo.copy(), lo.copy()
    args = (*arrays, np.asarray(probabilities, dtype=np.float64), r.count,
            np.asarray(r.low_of), np.asarray(r.high_of), np.asarray(r.slack_of))
    per_step = max(1, int(ends[-1]) if steps else 1) * 8
    # batches of steps between the time and the bar's looks: at most 50M entries' work,
    # and at least twenty looks over the whole induction
    done, batch = 0, max(1, min(50_000_000 // per_step, -(-steps // 20)))
    shown = progress_bar(progress, total=steps, desc="step-bounded induction", unit="step",
                         leave=False)
    try:
        while done < steps:
            if time.perf_counter() > deadline:
                raise TimeUp
            last = min(done + batch, steps)
            reach_steps(done, last, steps, order, ends, ahead, *args, lo, hi, lo2, hi2,
                        sense == "min", multi, picks, offsets)
            if (last - done) % 2 == 1:  # the kernel's last step wrote the other pair
                lo, lo2, hi, hi2 = lo2, lo, hi2, hi
            shown.update(last - done)
            done = last
    finally:
        shown.close()
    return HorizonSolution(lo, hi, steps, sense, order, back, ahead, multi,
                           None if why else picks, offsets, why, time.perf_counter() - t0)
