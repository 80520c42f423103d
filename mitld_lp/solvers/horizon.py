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
``lo_k <= v_k <= hi_k`` by induction.  A step that leaves both vectors unchanged is a
fixed point of the rounded operator (every later step gives the same): the induction
stops there, its answer that of all ``k`` steps.

The policy: for a maximum, at ``j + 1`` steps left, the choice best for ``lo_j``; its
value is at least ``lo`` (``lo_{j+1}(s) = below(P_c lo_j) <= P_c lo_j <= P_c
v^pi_j``); for a minimum the choice best for ``hi_j``, its value at most ``hi``.  Kept
as one row per step of the states with more than one choice (the narrowest unsigned
type), only within :data:`POLICY_MAX_BYTES`, checked before the work; the work, ``k``
times the transitions and choices, within :data:`MAX_WORK`, checked before it starts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mitld_lp.solvers.rounding import ETA, rounding
from mitld_lp.util.stops import TimeUp

__all__ = ["MAX_WORK", "POLICY_MAX_BYTES", "HorizonSolution", "HorizonTooLarge",
           "horizon_reach", "horizon_work", "policy_bytes"]

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
    """The bracket of ``v_k`` (``lo``, ``hi`` in every state), the steps ``k`` asked and
    the steps run (fewer at a fixed point), the policy (``policy[r, multi_of[s]]`` the
    local choice at state ``s`` with ``r + 1`` steps left, ``r`` clipped to the rows
    kept; ``None`` when it was not kept, ``why_no_policy`` then saying why)."""

    lo: np.ndarray
    hi: np.ndarray
    steps: int
    steps_run: int
    sense: str
    policy: np.ndarray | None
    multi_of: np.ndarray
    why_no_policy: str
    seconds: float

    def choice(self, state: int, steps_left: int) -> int | None:
        """The policy's local choice index at ``state`` with ``steps_left`` steps left
        (0 where the state has a single choice; None without a policy or steps)."""
        if self.policy is None or steps_left <= 0:
            return None
        k = int(self.multi_of[state])
        if k < 0:
            return 0
        row = min(steps_left, self.policy.shape[0]) - 1
        return int(self.policy[row, k])


def horizon_work(choices: np.ndarray, branches: np.ndarray, steps: int) -> int:
    """The induction's work: ``steps`` times the world's transitions and choices."""
    return steps * (int(branches[-1]) + int(choices[-1]))


def policy_bytes(choices: np.ndarray, steps: int) -> tuple[int, np.dtype]:
    """The bytes of the step-dependent policy and its entry type (module docs)."""
    per = np.diff(choices)
    widest = int(per.max(initial=1))
    dtype = np.dtype(np.uint8 if widest <= 256 else np.uint16 if widest <= 65536
                     else np.uint32)
    return steps * int(np.count_nonzero(per > 1)) * dtype.itemsize, dtype


def horizon_reach(choices: np.ndarray, branches: np.ndarray, targets: np.ndarray,
                  probabilities: np.ndarray, goal: np.ndarray, allowed: np.ndarray,
                  steps: int, sense: str = "max", *, eta: float = ETA,
                  max_work: int = MAX_WORK, policy_max_bytes: int = POLICY_MAX_BYTES,
                  time_limit: float | None = None) -> HorizonSolution:
    """The bracket of ``allowed U[0,steps] goal`` in every state of the world given by
    its arrays (:class:`mitld_lp.worlds.table.WorldTable`'s ``choices``, ``branches``,
    ``targets``, ``probabilities``), optimised in ``sense`` (module docs).  ``goal`` and
    ``allowed``: a bool per state.  Raises :class:`HorizonTooLarge` past ``max_work``
    (before any work), :class:`TimeUp` past ``time_limit`` seconds."""
    import scipy.sparse as sp

    from mitld_lp.solvers.horizon_kernels import reach_steps

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
    undecided = np.flatnonzero(allowed & ~goal).astype(np.int64)
    size, dtype = policy_bytes(choices, steps)
    multi = np.diff(choices) > 1
    multi_of = np.full(n, -1, dtype=np.int64)
    multi_of[multi] = np.arange(int(multi.sum()))
    why = ""
    if size > policy_max_bytes:
        why = (f"the step-dependent policy ({steps:,} steps x {int(multi.sum()):,} states "
               f"with a choice x {dtype.itemsize} byte(s) = {size:,} bytes) is past the "
               f"{policy_max_bytes:,} bytes of mitld_lp.solvers.horizon.POLICY_MAX_BYTES")
        policy = np.zeros((0, 0), dtype=np.uint8)
    else:
        policy = np.zeros((max(steps, 1), int(multi.sum())), dtype=dtype)
    matrix = sp.csr_array((probabilities, targets, branches), shape=(choices[-1], n))
    r = rounding(matrix, eta)
    lo = goal.astype(np.float64)
    hi = lo.copy()
    lo2, hi2 = lo.copy(), hi.copy()
    args = (choices.astype(np.int64, copy=False), branches.astype(np.int64, copy=False),
            targets.astype(np.int64, copy=False),
            probabilities.astype(np.float64, copy=False), r.count,
            np.asarray(r.low_of), np.asarray(r.high_of), np.asarray(r.slack_of))
    done, batch = 0, max(1, 10_000_000 // max(1, int(branches[-1]) + int(choices[-1])))
    while done < steps:
        if time.perf_counter() > deadline:
            raise TimeUp
        ask = min(batch, steps - done)
        ran = int(reach_steps(ask, done, undecided, *args, lo, hi, lo2, hi2,
                              sense == "min", multi_of, policy))
        if ran % 2 == 1:  # the kernel's last step wrote the other pair
            lo, lo2, hi, hi2 = lo2, lo, hi2, hi
        done += ran
        if ran < ask:  # a fixed point: every later step alike
            break
    kept = None if why else policy[:max(done, 1)]
    return HorizonSolution(lo, hi, steps, done, sense, kept, multi_of, why,
                           time.perf_counter() - t0)
