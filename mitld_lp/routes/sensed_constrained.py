"""The ``sensed-constrained`` route: constraints (and ``then``) with sensors that miss
their events, solved by the constrained occupancy LP on the information-state product.

The information-state MDP (:mod:`mitld_lp.sensing.belief`) is an ordinary MDP over what
the robot knows, so the constrained LP of :mod:`mitld_lp.solvers.constrained` applies to
it once every quantity is a linear function of its occupancy:

* **The joint automaton per hypothesis.**  The product is built on the joint automaton
  of the task and the constraints' formulas (:mod:`mitld_lp.automata.joint`): each
  hypothesis (when the sensed events happened) runs it.  A hypothesis ends when every
  component is decided, a component that can no longer accept (given the events still
  to come) counting as rejected; it then goes to one absorbing state per verdict tuple
  (:class:`Verdict`).  A probability is the mass entering the verdict states that
  accept its component, as on the fully observed product.
* **Staying for ever.**  A run may stay for ever in an end component of the
  information states; the hypotheses left there keep their verdicts (a co-safe
  component accepted stays accepted; one undecided never accepts inside an end
  component), the undecided ones counting as not satisfied.  Each information state of
  an end component gets a *stay* choice into the verdict states, by the posterior
  weights of its hypotheses' verdicts: the fully observed LP's stay with fractional
  values.  The controller that takes it plays the end component's choices for ever.
* **Keeping a safety part.**  For a task with a safety part (safety, obligation; a
  minimum's complement) a hypothesis is *persistent* when its task accepted or its task
  automaton's state is safe, *lost* when its task rejected or can no longer be won with
  the events left, else *open* (:func:`mitld_lp.running.sensed_joint.held`).  A *keep
  state* lies in a maximal end component of states with no open hypothesis, or else of
  states with some persistent hypothesis, in which each hypothesis is persistent in
  every state that holds it or in none (:class:`~mitld_lp.running.sensed_joint.Keeps`):
  playing that end component for ever keeps the true run's task exactly when its
  hypothesis is persistent there.  A keep state gets a *keep* choice instead of a
  stay: the task accepted for the persistent hypotheses, the constraints as they are,
  no step counted after it (with ``then`` or a bound on steps or costs only where no
  hypothesis is open: an open one would take steps for ever); a stay is offered only
  at other states with an open hypothesis
  (:meth:`mitld_lp.running.sensed_joint.JointEnds.stayed` tells the two apart on the
  chain).  Where an end component holds persistent hypotheses but no keep state
  (:func:`mixed_states`), the answer is a bracket (:mod:`mitld_lp.routes.sensed_kept`).
* **Steps and costs** count, at an information state from which the task can still be
  won (:func:`~mitld_lp.running.sensed_joint.winnable`), the posterior weight of its
  hypotheses whose task is still undecided (:attr:`Merged.share`): the expected number
  of steps taken while the true run's task is undecided and can be won, as on the
  fully observed product (a trap that keeps the task's automaton open for ever, a
  ditch that never reaches ``c`` of ``F c``, takes no steps and may be stayed in).
  A stay where that weight is positive would take infinitely many steps: it is not
  offered when steps or costs are bounded or minimised.  A run the chosen
  policy traps in information states (an interior-point solution's negligible flow on a
  loop) is worth what staying there is worth (:attr:`Merged.stay_values`), so the
  policy's certified values are its own.

Solved and certified as :mod:`mitld_lp.routes.constrained` solves the product: the
lower model (truncation fails the task and violates each constraint), a constraint the
certified bound misses tightened and solved again, the upper bound by weak duality.
The policy is randomised over information states, so a constraint holds in expectation
over observation histories (the fully observed route's semantics).  Its controller
(:mod:`mitld_lp.sensing.mixed`) is saved as the controller file's ``sensed-randomised``
kind; its controlled chain is :mod:`mitld_lp.running.sensed_chain`'s over the joint
automaton (:mod:`mitld_lp.running.sensed_joint`).

A world whose moves react to a sensed event is built by
:func:`mitld_lp.sensing.reacting.reacting_product` (exact posteriors, every sensor as
given as here, no states merged by their times); so is every candidate of a band's
routes (:mod:`mitld_lp.routes.sensed_band_constrained`, its worst law;
:mod:`mitld_lp.routes.sensed_optimistic_constrained`, its best), which build their
candidates here.

A sensor with false alarms on a law that may never happen is built blind, its reports
dropped by the controller, and the answer bracketed between that constrained optimum and
a sensor without false alarms at least as informative
(:mod:`mitld_lp.routes.sensed_never`).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from mitld_lp.automata.dta import DTA
from mitld_lp.automata.joint import ACCEPTED, REJECTED, UNDECIDED, Joint
from mitld_lp.logic.fragment import CO_SAFE
from mitld_lp.mdp import ABSORB, MDP
from mitld_lp.product import Absorbing
from mitld_lp.routes.constrained import ConstrainedPart, lp_refusals, solve_merged
from mitld_lp.routes.route import Route
from mitld_lp.routes.sensed import sensed_refusals
from mitld_lp.sensing.sensors import partial
from mitld_lp.solvers.quotient import maximal_end_components

if TYPE_CHECKING:
    from mitld_lp.problem import Posed
    from mitld_lp.result import Result
    from mitld_lp.routes.stages import Built
    from mitld_lp.running.sensed_joint import Keeps
    from mitld_lp.sensing.belief import Belief, InfoState, Reaches
    from mitld_lp.solvers.constrained_model import Merged

__all__ = ["SensedConstrainedRoute", "SensedConstrainedPart", "Verdict", "JointEnds",
           "info_merged", "mixed_states", "STAY"]

log = logging.getLogger(__name__)

STAY = "(stay)"
"""The name of a stay choice in the policy's table."""


@dataclass(frozen=True, slots=True)
class Verdict:
    """An absorbing state of the information-state product on a joint automaton: the
    hypotheses that end with these verdicts, one per component (the task first),
    :data:`~mitld_lp.automata.joint.ACCEPTED` or ``REJECTED``."""

    verdicts: tuple[int, ...]

    def __str__(self) -> str:
        return "verdict(" + ", ".join("accepted" if v == ACCEPTED else "rejected"
                                      for v in self.verdicts) + ")"


class JointEnds:
    """Where a hypothesis of the joint automaton ends
    (:data:`mitld_lp.sensing.belief.Ends`): a :class:`Verdict` once every component is
    decided, a component that can no longer accept counting as rejected.  ``seen``
    keeps each undecided hypothesis's verdicts (automaton state, events left) for the
    stays and the steps' shares."""

    def __init__(self, joint: Joint) -> None:
        self.joint = joint
        self.seen: dict[tuple[int, frozenset[str]], tuple[int, ...]] = {}

    def __call__(self, q: int, left: frozenset[str], reaches: Reaches) -> Hashable | None:
        key = (q, left)
        v = self.seen.get(key)
        if v is None:
            v = self.seen[key] = tuple(
                _effective(part, c, verdict, left, reaches) for part, c, verdict in zip(
                    self.joint.parts, self.joint.components[q], self.joint.verdicts[q],
                    strict=True))
        return None if UNDECIDED in v else Verdict(v)


def _effective(part: DTA, q: int, verdict: int, left: frozenset[str],
               reaches: Reaches) -> int:
    if verdict == UNDECIDED and not reaches(part, q, left):
        return REJECTED
    return verdict


def _verdicts_of(belief: Belief, ends: JointEnds, s: InfoState) -> list[tuple[int, ...]]:
    """The verdicts of each hypothesis of ``s``, in its order (its times: one per sensed
    event, then the report counts of the sensors with false alarms, not read here)."""
    from mitld_lp.sensing.belief import NOT_YET  # the sensed modules load when solving
    out = []
    n = len(belief.sensed)
    for times, q in s.hypotheses:
        waiting = frozenset(a for a, k in zip(belief.sensed, times[:n], strict=True)
                            if k == NOT_YET)
        out.append(ends.seen[(q, s.pending | waiting)])
    return out


def info_merged(belief: Belief, ends: JointEnds, *, timed: bool,
                keeps: Keeps | None = None, relaxed: bool = False) -> Merged:
    """The information-state product on a joint automaton as the constrained LP's
    model (module docs): its verdict states, a stay choice (action ``ABSORB``, marked
    ``keep``) at each information state of an end component (where no hypothesis's
    task is undecided when ``timed``), and the steps' shares.  For a task with a safety
    part (``keeps``, :func:`~mitld_lp.running.sensed_joint.keeps_for`): a *keep*
    choice (the task accepted for the persistent hypotheses) at each keep state (where
    ``timed``, only those with no open hypothesis), a stay only at the other states
    with an open hypothesis
    (:meth:`mitld_lp.running.sensed_joint.JointEnds.stayed` tells them apart), and with
    ``relaxed`` (the upper end) a credited keep at every other state of an end
    component with some persistent hypothesis (:func:`mixed_states`)."""
    from mitld_lp.running.sensed_joint import winnable
    from mitld_lp.sensing.belief import InfoState
    from mitld_lp.solvers.constrained_model import Merged

    mdp = belief.mdp
    records: list[Any] = list(mdp.states)
    n, k = len(records), len(ends.joint.parts)
    info = np.array([isinstance(r, InfoState) for r in records], dtype=bool)
    share = np.zeros(n)
    worth = np.zeros((n, k))  # staying for ever: the weight of each component accepted
    plain: list[dict[Verdict, float]] = [{} for _ in range(n)]
    for i in np.flatnonzero(info).tolist():
        s = records[i]
        row = worth[i]
        for w, v in zip(s.weights, _verdicts_of(belief, ends, s), strict=True):
            share[i] += w if v[0] == UNDECIDED else 0.0
            for j, x in enumerate(v):  # w on each component accepted (0.0 added elsewhere)
                if x == ACCEPTED:
                    row[j] += w
            _add(plain[i], v, None, w)
    share *= winnable(belief, keeps)  # no step counts where the task is lost
    mecs = maximal_end_components(mdp, info)
    in_mec = (np.asarray(mecs.mec_of) >= 0) & info
    extra: dict[int, dict[Verdict, float]] = {}
    keep_internal = np.zeros(mdp.n_choices, dtype=bool)
    if keeps is not None:
        usable = keeps.states & ~(timed & keeps.open_keeps)
        keep_internal = keeps.inside & usable[mdp.choice_state()]
        for i in np.flatnonzero(in_mec & ~keeps.every & ~keeps.states
                                & ~(timed & (share > 0))).tolist():
            extra[i] = plain[i]
        credited = usable | (mixed_states(keeps, timed) if relaxed else False)
        for i in np.flatnonzero(credited).tolist():
            extra[i] = _credited(belief, ends, records[i], keeps.status[i])
    else:
        for i in np.flatnonzero(in_mec & ~(timed & (share > 0))).tolist():
            extra[i] = plain[i]
    index = {r: i for i, r in enumerate(records) if isinstance(r, Verdict)}
    for t in extra.values():
        for end in t:
            if end not in index:
                index[end] = len(records)
                records.append(end)
    m = len(records)
    stays = np.zeros(n, dtype=bool)
    stays[list(extra)] = True
    # the rows: each state's own, then its stay; a new verdict state's self-loop
    rg = np.asarray(mdp.row_groups, dtype=np.int64)
    counts = np.concatenate([np.diff(rg) + stays, np.ones(m - n, dtype=np.int64)])
    groups = np.zeros(m + 1, dtype=np.int64)
    np.cumsum(counts, out=groups[1:])
    owner = mdp.choice_state()
    old_pos = groups[owner] + (np.arange(owner.size) - rg[owner])
    stay_pos = groups[np.flatnonzero(stays)] + np.diff(rg)[stays]
    coo = mdp.matrix.tocoo()
    rows, cols, vals = [old_pos[coo.row]], [coo.col], [coo.data]
    for s, pos in zip(np.flatnonzero(stays).tolist(), stay_pos.tolist(), strict=True):
        for end, w in extra[s].items():
            rows.append(np.array([pos]))
            cols.append(np.array([index[end]]))
            vals.append(np.array([w]))
    new = np.arange(n, m)
    rows.append(groups[new])
    cols.append(new)
    vals.append(np.ones(m - n))
    n_choices = int(groups[-1])
    matrix = sp.csr_array((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n_choices, m))
    matrix.sum_duplicates()
    actions = np.full(n_choices, ABSORB, dtype=np.int32)
    actions[old_pos] = mdp.choice_actions
    keep = np.zeros(n_choices, dtype=bool)
    keep[stay_pos] = True
    kept_choice = np.zeros(n_choices, dtype=bool)
    kept_choice[old_pos] = keep_internal
    verdicts = np.full((m, k), UNDECIDED, dtype=np.int64)
    for r, i in index.items():
        verdicts[i] = r.verdicts
    absorbing = np.ones(m, dtype=bool)
    absorbing[:n] = ~info
    truncated = np.array([r is Absorbing.TRUNCATED for r in records], dtype=bool)
    accepted = verdicts[:, 0] == ACCEPTED
    merged_mdp = MDP(matrix=matrix, row_groups=groups, choice_actions=actions,
                     action_names=mdp.action_names, initial=mdp.initial,
                     target=absorbing & accepted, sink=absorbing & ~accepted & ~truncated,
                     truncated=truncated, states=tuple(records))
    share = np.concatenate([share, np.zeros(m - n)])
    origin = np.where(np.arange(m) < n, np.arange(m), -1)
    origin[absorbing] = -1
    choice_origin = np.full(n_choices, -1, dtype=np.int64)
    choice_origin[old_pos] = np.arange(owner.size)
    return Merged(merged_mdp, origin, np.arange(n), np.full(m, -1, dtype=np.int64), verdicts,
                  absorbing, truncated, share > 0, np.zeros(m, dtype=bool),
                  np.zeros(n_choices, dtype=bool), keep, kept_choice,
                  np.arange(n), choice_origin, share,
                  np.concatenate([worth, np.zeros((m - n, k))]))


def _add(targets: dict[Verdict, float], v: tuple[int, ...], task: int | None,
         w: float) -> None:
    """Add weight ``w`` to the verdict state of ``v`` (the task's verdict ``task`` if
    given), an undecided component counting as rejected."""
    end = Verdict(tuple(REJECTED if x == UNDECIDED else x for x in
                        (v if task is None else (task, *v[1:]))))
    targets[end] = targets.get(end, 0.0) + w


def _credited(belief: Belief, ends: JointEnds, s: InfoState, status: list[bool | None]
              ) -> dict[Verdict, float]:
    """A keep's ends at ``s``: the task accepted for the persistent hypotheses
    (``status`` True), the constraints as they are."""
    out: dict[Verdict, float] = {}
    for w, v, kept in zip(s.weights, _verdicts_of(belief, ends, s), status, strict=True):
        _add(out, v, ACCEPTED if kept else REJECTED, w)
    return out


def mixed_states(keeps: Keeps | None, timed: bool) -> np.ndarray | bool:
    """The information states in an end component of states with some persistent
    hypothesis where the lower end keeps nothing (no keep state, or one with an open
    hypothesis where ``timed``: staying there takes steps for ever) and the upper end
    credits the persistent hypotheses (module docs); False without ``keeps``."""
    if keeps is None:
        return False
    return keeps.in_some & ~(keeps.states & ~(timed & keeps.open_keeps))


@dataclass(frozen=True, slots=True, eq=False)
class SensedConstrainedPart(ConstrainedPart):
    """The ``sensed-constrained`` route's part of the answer: the constrained route's
    (its ``merged`` model the information states, :func:`info_merged`), each sensed
    event's sensor, and the information-state product's record."""

    sensors: Mapping[str, Any] = field(default_factory=dict)
    belief: Any = None
    observation_based = True

    def policy_table(self, result: Result) -> list[dict[str, Any]]:
        """One row per (information state, choice) the policy takes with positive
        probability: the world state, the clock, the reports, the hypotheses' number,
        the action (:data:`STAY` for staying for ever) and its probability."""
        from mitld_lp.sensing.belief import InfoState

        m = self.merged
        if self.prob is None or m is None:
            return []
        cs = m.mdp.choice_state()
        rows = []
        for c in np.flatnonzero(self.prob > 0).tolist():
            s = m.mdp.states[int(cs[c])]
            if not isinstance(s, InfoState):
                continue
            rows.append({"game_state": s.world, "clock": s.clock,
                         "reported": sorted(s.reported), "hypotheses": len(s.hypotheses),
                         "action": STAY if m.keep[c] else m.mdp.action_name(c),
                         "probability": float(self.prob[c])})
        return rows


class SensedConstrainedRoute(Route):
    """Constraints or a ``then`` objective with a sensor that misses its event (module
    docs).  ``every``: it claims sensed problems without constraints too (the trade-off
    curve's end points)."""

    name = "sensed-constrained"
    takes_constraints = True
    observation_based = True

    def __init__(self, *, every: bool = False) -> None:
        self.every = every

    def claims(self, posed: Posed) -> bool:
        return bool(partial(posed.model.sensors)) and (posed.problem.constrained or self.every)

    def refusal(self, posed: Posed) -> list[str]:
        p = posed.problem
        refused = lp_refusals(posed)  # the task's class, the constraints' formulas
        # the sensors' own conditions (false alarms, bands, laws that may never happen,
        # worlds that react to a sensed event); the task's are said above
        # (constraints or then: a band is refused with them, by name)
        asked = (*p.constraints, *([p.then] if p.then else []))
        # the constrained LP asked with neither (a trade-off curve's end) is this LP too
        lp = asked or (("the constrained LP",) if self.every and not posed.robust else ())
        return refused + timed_minimum_refusal(posed) + sensed_refusals(
            p.model, CO_SAFE, "max", lp, None, posed.robust, never=True)

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        """The joint automaton of the task and the constraints' formulas, then the
        information-state product on it (module docs), under the problem's budgets."""
        from mitld_lp.routes.sensed_never import blind_model, dropping, never_alarms
        from mitld_lp.routes.stages import Built, joint_sta
        from mitld_lp.sensing.belief import belief_product
        from mitld_lp.sensing.reacting import reacting_product
        from mitld_lp.sensing.sensors import reacting_events

        model, s = posed.model, posed.settings
        blind = never_alarms(model)  # built blind, their reports dropped (sensed_never)
        if blind:
            model = blind_model(model)
        assert s.max_states is not None  # resolved
        t0 = time.perf_counter()
        # a sensed band that may never happen, or that no truncation serves: the belief
        # product truncates it (its never mass a hypothesis of its own, its tail bounded:
        # sensing.belief.sensed_sta); only the joint automaton's laws are read here,
        # which a point for it lets make_sta give
        never_bands = tuple((a, 1) for a, d in sorted(model.distributions.items())
                            if d.is_ambiguous and a in partial(model.sensors)
                            and a not in (s.truncation_map or {}))
        joint, sta = joint_sta(replace(posed, settings=replace(
            s, truncation=(*(s.truncation or ()), *never_bands))) if never_bands else posed)
        laws = {a: c.distribution for a, c in sta.clocks.items()}
        t1 = time.perf_counter()
        ends = JointEnds(joint)
        # a world that reacts to a sensed event: its own product (exact posteriors; every
        # sensor built as given, as here, but no states merged by their times)
        reacts = reacting_events(model.game, partial(model.sensors))
        belief = (reacting_product if reacts else belief_product)(
            model.game, joint.dta, laws, partial(model.sensors),
            model.epsilon if s.epsilon is None else s.epsilon,
            clock_reduction=s.clock_reduction, truncation=s.truncation_map,
            max_states=s.max_states, max_memory=s.max_memory, progress=progress,
            ends=ends, name=model.name, **({} if reacts else {"late_reports": False}))
        if blind:
            belief = dropping(belief, posed.model)
        return Built(joint.dta, belief.sta, belief.mdp,
                     {"automaton": t1 - t0, "product": time.perf_counter() - t1},
                     joint, belief=(belief, ends))

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.routes.sensed_never import never_alarms, solve_never

        result = self._solve(posed, built, costs=costs, seed=seed)
        if not never_alarms(posed.model) or posed.robust:
            return result
        from mitld_lp.routes.constrained import ConstrainedRoute

        # false alarms at a law that may never happen: ``result`` is the blind end's; the
        # informed end on this route, or the constrained one where no sensor is left
        return solve_never(posed, result, (SensedConstrainedRoute(every=True),
                                           ConstrainedRoute(every=True)), costs=costs)

    def _solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None,
               seed: int | None) -> Result:
        from mitld_lp.routes.sensed_kept import bracketed
        from mitld_lp.sensing.mixed import mixed_controller
        from mitld_lp.solvers.rounding import model_eta

        assert built.joint is not None and built.belief is not None  # built above
        belief, ends = built.belief
        t0 = time.perf_counter()
        p = posed.problem
        timed = p.then is not None or any(c.kind != "prob" for c in p.constraints)
        from mitld_lp.running.sensed_joint import keeps_for

        keeps = keeps_for(belief, ends.joint)
        merged = info_merged(belief, ends, timed=timed, keeps=keeps)
        eta = model_eta(belief.sta, history=True)

        def part(**kw: Any) -> SensedConstrainedPart:
            return SensedConstrainedPart(**kw, sensors=dict(belief.sensors), belief=belief)

        def solve(merged: Merged, controller: Any) -> Result:
            assert built.joint is not None
            return solve_merged(posed, belief.mdp, built.joint, belief.sta, t0, costs=costs,
                                seed=seed, build=built.timings, merged=merged, eta=eta,
                                route=self.name, part=part, controller=controller)

        exact = _steps_checked(solve(merged, lambda merged, chosen: mixed_controller(
            posed.model.game, belief, merged, chosen.prob, Verdict, seed=seed)), p.then)
        mixed = np.asarray(mixed_states(keeps, timed))
        if not mixed.any():
            return exact
        log.info("sensed constraints: %d information states lie in end components that "
                 "keep some hypotheses persistent and not others: the upper end credits "
                 "them (module docs)", int(mixed.sum()))
        relaxed = solve(info_merged(belief, ends, timed=timed, keeps=keeps, relaxed=True),
                        lambda merged, chosen: None)
        return bracketed(exact, relaxed, int(mixed.sum()), posed.minimise,
                         posed.settings.precision)


def _steps_checked(r: Result, then: str | None) -> Result:
    """``r`` not certified where ``then`` minimised the expected steps or cost and the
    policy's chain may stay undecided for ever (its certified expected steps infinite,
    :func:`mitld_lp.solvers.certify_mixture.mixture_bounds`), with the check saying so."""
    from dataclasses import replace

    from mitld_lp.checks import Check

    steps = getattr(r.part, "steps", float("nan"))
    if then is None or not np.isinf(steps):
        return r
    check = Check("expected steps", False, (
        f"then {then}: the policy's chain may stay undecided for ever (infinitely many "
        "expected steps), where the LP's policy takes finitely many"))
    return replace(r, certified=False, checks=(*r.checks, check))


def timed_minimum_refusal(posed: Posed) -> list[str]:
    """A minimum with expected steps or costs (``then``, ``E(steps)``, ``E(cost)``): the
    information-state product counts them while the automaton it solves, the complement
    of a minimised task, is undecided and can still be won, which is not while the posed
    task is (a state from which every run satisfies the task would go uncharged), so the
    combination is refused by name until the sensed steps are counted on the posed task."""
    p = posed.problem
    timed = [str(c) for c in p.constraints if c.kind in ("steps", "cost")]
    timed += [f"then {p.then}"] if p.then else []
    if not posed.minimise or not timed:
        return []
    return [f"objective min with {', '.join(timed)} and a sensor: the sensed routes count "
            "steps and costs on the complement a minimum is solved as, not until the "
            "posed task is decided (without a sensor the constrained route counts them on "
            "the posed task)"]
