"""Information states merged where their futures are identical: the times of a sensed
event that the future cannot tell apart, shifted to a canonical place
(:mod:`mitld_lp.sensing.frontier` calls :meth:`Shifts.canonical` on each new group of
hypotheses before it looks the state up).

The claim.  Take a sensed event ``a`` whose law's hazard (as the build reads it,
:meth:`~mitld_lp.automata.sta.EventClock.hazard`) is one value ``h`` at every clock from
``c - 1`` to its truncation point ``T`` less one, so that ``P(K = k + 1) = (1 - h)
P(K = k)`` for ``c <= k < T``; its sensor neither keeps "never" nor cuts at a number of
misses (``keeps_never``, ``report_limit``: the miss count would matter).  In an
information state in which every hypothesis has ``a`` happened (``k_a >= 1``) and either
reported or due (``k_a + delay <= t + 1``, its report can come at every step from now
on), shifting every hypothesis's ``k_a`` down by the same ``s`` (its least ``m`` to
``c``, where ``m > c``) gives a state with the same future:

* the *dynamics*: a hypothesis's further steps read ``k_a`` only through whether it is
  not yet happened, never, reported, or not due, and the miss count under a report
  limit (:meth:`~mitld_lp.sensing.rules.StepRules.sensed_branches`); none of these
  changes (reported stays reported, due stays due: the clock the state keeps is at
  least ``max k_a + delay``, and after the shift at least the shifted one); the
  automaton's state is in the hypothesis, and ``a`` has happened, so it never reads
  ``a`` again; the clock the state keeps (:meth:`~mitld_lp.sensing.rules.StepRules.
  clock_key`) is read by the other events only up to their own needs, which the shift
  leaves alone;
* the *posterior*: a hypothesis's weight is its prior times the likelihood of what was
  observed, a product over the sensed events (independent laws; the world ignores the
  sensed events) of ``P(K_a = k_a)`` and ``(1 - d)`` per missed report of ``a``
  (``(1 - d)^(r - k_a - delay) d`` reported at step ``r``, ``(1 - d)^(t + 1 - k_a -
  delay)`` not yet), times factors common to every hypothesis (the world's moves, the
  other events' factors, which the shift does not touch).  Shifting ``k_a`` by ``s``
  multiplies ``P(K_a = k_a)`` by ``(1 - h)^(-s)`` and ``(1 - d)^(-k_a)`` by ``(1 -
  d)^s``, the same for every hypothesis: the normalised weights are unchanged.

So the two states have the same conditional law of everything that follows (the
observations, the verdicts, with the same probabilities under every policy), hence the
same optimum, and the weights stay a function of the key (the build's check of every
revisit, ``WEIGHT_TOL``, still holds).  The shift is the same for every hypothesis of
the state, so distinct hypotheses stay distinct.  Inside an end component no shift
happens (a state's least ``k_a`` rises only when a hypothesis leaves: its mass goes to
an end, or the state held one not happened or not due, whose clock then runs, so the
state is on no cycle), so a hypothesis keeps its times there, as
:mod:`mitld_lp.routes.sensed_mixed` and :mod:`mitld_lp.running.sensed_joint` read them.
tests/test_sensing_merge.py checks the claim on exact posteriors over every observation
history of a small case, and the optimum with and without the merge."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from mitld_lp.automata.sta import STA
from mitld_lp.sensing.rows import INT, compiled_on, groups, scatter
from mitld_lp.sensing.sensors import Sensor

__all__ = ["Shifts", "Counts", "shift_start"]


def grown(array: np.ndarray, times: list[tuple[int, ...]]) -> np.ndarray:
    """``array`` (the first rows of ``times`` as a matrix) with the rows of the times
    added since: only the new tuples are converted (the whole list was, at every
    chunk, some 0.5 s of a build with false alarms' hundred thousand times)."""
    if len(array) >= len(times):
        return array
    new = np.asarray(times[len(array):], INT).reshape(len(times) - len(array), -1)
    return np.concatenate([array, new]) if len(array) else new


def shift_start(sta: STA, event: str) -> int | None:
    """The least ``c >= 1`` with ``P(K = k + 1) = (1 - h) P(K = k)`` for ``c <= k <
    T`` at the hazards the build reads (module docs), None where the event's times
    cannot be shifted (a law kept to "never", a report limit, no truncation point)."""
    clock = sta.clocks[event]
    T = clock.truncation
    if T is None or T < 1 or clock.keeps_never or clock.report_limit is not None:
        return None
    hz = [clock.hazard(t) for t in range(T)]  # the step after t steps: k = t + 1
    t0 = T - 1
    while t0 > 0 and hz[t0 - 1] == hz[T - 1]:
        t0 -= 1
    return t0 + 1


class Shifts:
    """The canonical times of the sensed events ``sensed`` (in the build's order) with
    their ``sensors``; ``times`` and ``time_id`` the build's table of hypotheses' times
    and its lookup (a new tuple gets a new id).  ``enabled=False``: no shift."""

    def __init__(self, sta: STA, sensed: tuple[str, ...], sensors: Mapping[str, Sensor],
                 times: list[tuple[int, ...]], time_id: Callable[[tuple[int, ...]], int],
                 enabled: bool = True) -> None:
        found = {i: shift_start(sta, a) for i, a in enumerate(sensed)} if enabled else {}
        self.start = {i: c for i, c in found.items() if c is not None}
        self.delay = [sensors[a].delay for a in sensed]
        self.times, self.time_id = times, time_id
        self.array = np.zeros((0, len(sensed)), INT)
        self.merged = 0  # the groups shifted, for the log

    def canonical(self, tid: np.ndarray, group: np.ndarray, c: np.ndarray,
                  c_state: np.ndarray, reported: np.ndarray, new: np.ndarray,
                  clock: np.ndarray) -> np.ndarray:
        """The hypotheses' times ``tid`` (one per row, ``group`` each row's group of
        one observation, ``c_state[c]`` its parent state's place in ``reported`` and
        ``clock``, ``new`` the reports the step made) with each group's shiftable events
        shifted (module docs)."""
        if not self.start or len(tid) == 0:
            return tid
        self.array = grown(self.array, self.times)
        n = int(group.max()) + 1
        if compiled_on():  # the same shifts by one kernel pass
            from mitld_lp.sensing.group_kernels import group_shifts

            shift = group_shifts(self.array, tid, group, n, c, c_state, reported, new,
                                 clock, np.array(list(self.start), INT),
                                 np.array(list(self.start.values()), INT),
                                 np.array(self.delay, INT))
        else:
            row = c_state[c]
            shift = self.numpy_shifts(tid, group, row, reported[row] | new, clock, n)
        moved = shift.any(axis=1)
        if not moved.any():
            return tid
        self.merged += int(moved.sum())
        rows = np.flatnonzero(moved[group])
        by = shift[group[rows]]  # each row's shift: one new id per (times, shift)
        pair, first = groups(tid[rows], *by.T)
        new_id = np.array([self.time_id(tuple(x)) for x in
                           (self.array[tid[rows][first]] - by[first]).tolist()], INT)
        out = tid.copy()
        out[rows] = new_id[pair]
        return out

    def numpy_shifts(self, tid: np.ndarray, group: np.ndarray, row: np.ndarray,
                     said: np.ndarray, clock: np.ndarray, n: int) -> np.ndarray:
        """Each group's shift of each event's times (:meth:`canonical`), by NumPy."""
        k = self.array[tid]
        shift = np.zeros((n, k.shape[1]), INT)
        for i, c in self.start.items():
            ki = k[:, i]
            ok = (ki > 0) & (((said >> i) & 1 == 1) | (ki + self.delay[i] <= clock[row] + 1))
            good = np.ones(n, bool)
            np.logical_and.at(good, group, ok)
            least = np.full(n, np.iinfo(INT).max, INT)
            scatter("min", least, group, ki)
            shift[:, i] = np.where(good & (least > c), least - c, 0)
        return shift


class Counts:
    """The canonical report counts of the sensed events whose sensors give false alarms
    (:mod:`mitld_lp.sensing.rules`: each hypothesis keeps, after its events' times, the
    number of reports of each such event before its report was due, ``b``).

    The claim.  In one information state every hypothesis saw the same reports.  Under
    hypothesis ``k`` the reports' likelihood is ``fa^b (1 - fa)^(p - b) d^(r - b)
    (1 - d)^(n - p - r + b)``, ``p = min(t, k + delay - 1)`` its steps before due, ``r``
    the reports and ``n`` the steps in all (common to every hypothesis): the normalised
    weights depend on the counts ``b`` only through their differences (a factor
    ``(fa (1 - d) / (d (1 - fa)))^b`` beside one of ``k`` and ``t``), and the future
    adds to a count, never reads it.  So subtracting from every hypothesis's count of an
    event the least count of that event in the state leaves the posterior and the
    future unchanged, and two states whose counts differ by a constant are one.  The
    build's check that a key's posterior never changes (``WEIGHT_TOL``) checks this
    claim at every revisit."""

    def __init__(self, n: int, alarms: tuple[int, ...], times: list[tuple[int, ...]],
                 time_id: Callable[[tuple[int, ...]], int]) -> None:
        self.n, self.alarms = n, alarms
        self.times, self.time_id = times, time_id
        self.array = np.zeros((0, n + len(alarms)), INT)

    def canonical(self, tid: np.ndarray, group: np.ndarray) -> np.ndarray:
        """The hypotheses' times ``tid`` (one per row, ``group`` each row's group of one
        observation) with each group's counts lowered by their least (class docs)."""
        if not self.alarms or len(tid) == 0:
            return tid
        self.array = grown(self.array, self.times)
        if compiled_on():  # the same rows and counts by one kernel pass
            from mitld_lp.sensing.group_kernels import least_counts

            rows, by = least_counts(np.ascontiguousarray(self.array[:, self.n:]),
                                    tid, group, int(group.max()) + 1)
        else:
            b = self.array[tid][:, self.n:]
            least = np.full((int(group.max()) + 1, b.shape[1]), np.iinfo(INT).max, INT)
            for j in range(b.shape[1]):
                scatter("min", least[:, j], group, b[:, j])
            rows = np.flatnonzero(least[group].any(axis=1))
            by = least[group[rows]]
        if len(rows) == 0:
            return tid
        pair, first = groups(tid[rows], *by.T)
        shifted = self.array[tid[rows][first]].copy()
        shifted[:, self.n:] -= by[first]
        new_id = np.array([self.time_id(tuple(x)) for x in shifted.tolist()], INT)
        out = tid.copy()
        out[rows] = new_id[pair]
        return out
