"""The ``sensed`` route (:class:`SensedRoute`): a problem with a sensor that misses its
event, solved on the information-state product; which such problems it solves, and the
refusal naming each combination it does not (:func:`mitld_lp.synthesis.pose` raises it)."""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from mitld_lp.routes.route import Route
from mitld_lp.sensing.sensors import partial
from mitld_lp.worlds.game import GameError, world_members

if TYPE_CHECKING:
    from mitld_lp.problem import Posed
    from mitld_lp.result import Result
    from mitld_lp.routes.stages import Built

__all__ = ["SensedRoute", "task_automaton", "sensed_refusals", "false_alarm_refusal"]


class SensedRoute(Route):
    """Some event is reported by a sensor that misses it (``detect < 1``) or gives false
    alarms (at laws that surely happen): every task class, either objective, laws that
    may never happen (with false alarms bracketed: :mod:`mitld_lp.routes.sensed_never`);
    point laws, no constraints
    (:mod:`mitld_lp.routes.sensed_solve`), and a law known within a band (the worst case
    over it, :mod:`mitld_lp.routes.sensed_band`; with false alarms too where its laws
    surely happen).  It claims every
    problem with such a sensor: the fully observed product would answer another one."""

    name = "sensed"
    observation_based = True

    def claims(self, posed: Posed) -> bool:  # constraints: the sensed-constrained route
        return bool(partial(posed.model.sensors)) and not posed.problem.constrained

    def refusal(self, posed: Posed) -> list[str]:
        p = posed.problem
        if not partial(p.model.sensors):
            return ["sensed route: no event has a sensor that misses it"]
        return sensed_refusals(p.model, posed.fragment, p.objective, p.constraints, p.then,
                               posed.robust, never=True, worst=not self.optimistic,
                               best=self.optimistic)

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        """The task's automaton, then the information-state product
        (:mod:`mitld_lp.sensing.belief`: what the robot knows of the events, never the
        events themselves), under the problem's budgets."""
        from mitld_lp.routes.sensed_never import blind_model, dropping, never_alarms
        from mitld_lp.routes.stages import Built
        from mitld_lp.sensing.belief import belief_product

        model, s = posed.model, posed.settings
        blind = never_alarms(model)  # built blind, their reports dropped (sensed_never)
        if blind:
            model = blind_model(model)
        t0 = time.perf_counter()
        dta, direct = task_automaton(posed)
        t1 = time.perf_counter()
        belief = belief_product(model.game, dta, model.distributions, partial(model.sensors),
                                model.epsilon if s.epsilon is None else s.epsilon,
                                clock_reduction=s.clock_reduction,
                                truncation=s.truncation_map, max_states=s.max_states,
                                max_memory=s.max_memory, progress=progress,
                                name=model.name)
        if blind:
            belief = dropping(belief, posed.model)
        return Built(dta, belief.sta, belief.mdp,
                     {"automaton": t1 - t0, "product": time.perf_counter() - t1},
                     belief=belief, sense="min" if direct else "max")

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        from mitld_lp.routes.sensed_never import never_alarms, solve_never, solve_never_band
        from mitld_lp.routes.sensed_solve import solve_sensed

        if never_alarms(posed.model) and posed.robust:  # bracketed under the band
            from mitld_lp.routes.robust import RobustRoute

            # the informed end read as this route reads the band (its best law on the
            # optimistic route, a subclass), or the robust route where no sensor is left
            return solve_never_band(posed, self._solve(posed, built),
                                    (type(self)(), SensedRoute(), RobustRoute()))
        if never_alarms(posed.model):  # bracketed (sensed_never)
            from mitld_lp.routes.plain import PlainRoute

            # the informed end on this route, or the plain one where no sensor is left
            return solve_never(posed, solve_sensed(posed, built), (SensedRoute(), PlainRoute()))
        return self._solve(posed, built)

    def _solve(self, posed: Posed, built: Built) -> Result:
        """The problem on the product ``built`` (blind where :meth:`build` made it so):
        with a band its worst case (:mod:`mitld_lp.routes.sensed_band`), else the
        point-law solve."""
        from mitld_lp.routes.sensed_solve import solve_sensed

        if posed.robust:  # the worst case over the band (mitld_lp.routes.sensed_band)
            from mitld_lp.routes.sensed_band import solve_sensed_band

            return solve_sensed_band(posed, built)
        return solve_sensed(posed, built)


def task_automaton(posed: Posed) -> tuple[Any, bool]:
    """The task's automaton as the sensed routes solve it, and whether a minimum is
    solved on it directly: a minimum as the plain route poses it (a co-safe task
    minimised on its own automaton, any other as its complement's maximum read back);
    with a band every one as its complement's maximum (the robust route's reading,
    nature minimising it: :mod:`mitld_lp.routes.sensed_band`)."""
    from mitld_lp.automata.translate import to_dta
    from mitld_lp.routes.stages import reaching

    s = posed.settings
    assert s.max_states is not None and s.max_automaton_states is not None  # resolved
    dta = to_dta(posed.model.spec, max_states=min(s.max_states, s.max_automaton_states))
    direct = posed.minimise and reaching(dta) and not posed.robust
    return (dta.complement() if posed.minimise and not direct else dta), direct


def sensed_refusals(model: Any, fragment: str, objective: str, constraints: Sequence[Any],
                    then: str | None, robust: bool, *, never: bool = False,
                    worst: bool = False, best: bool = False) -> list[str]:
    """Why the ``sensed`` route cannot solve this problem as posed: every reason, each
    naming its feature (empty: it can).  ``model`` has at least one sensor that is not
    perfect.  Every caller builds sensors with false alarms at a point law that surely
    happens; ``never``: it also brackets them at a law that may never happen (the
    ``sensed`` route, :mod:`mitld_lp.routes.sensed_never`); ``worst``: it also solves
    them under a band read for its worst law, without constraints (the ``sensed`` route,
    :mod:`mitld_lp.routes.sensed_band`); ``best``: under a band read for its best law
    (the optimistic sensed routes, :mod:`mitld_lp.routes.sensed_optimistic`)."""
    sensors = partial(model.sensors)
    named = ", ".join(f"{a} = {s}" for a, s in sensors.items())
    head = f"sensors ({named})"
    refused = []
    for a, s in sensors.items():
        if s.false_alarm:
            refused += false_alarm_refusal(a, s.false_alarm, model.distributions.get(a),
                                           never=never, robust=robust, worst=worst,
                                           best=best)
    if robust:
        refused += band_refusals(model, head, objective, constraints)
    try:
        reacts = world_members(model.game).event_names
    except GameError:  # the model's loader checked the world; nothing to add here
        reacts = frozenset()
    for a in sorted(reacts & set(sensors)) if not constraints else ():
        refused.append(f"sensors.{a}: the world's moves react to the sensed event {a!r} "
                       "(event_names): solved by route sensed-reacting (with a band too, "
                       "its worst or best law; with constraints or then, sensed-constrained)"
                       ", which this list of routes does not hold")
    return refused


def false_alarm_refusal(event: str, false_alarm: float, law: Any, *, never: bool = False,
                        robust: bool = False, worst: bool = False, best: bool = False
                        ) -> list[str]:
    """Why a sensor with false alarms is not solved as posed (empty: it is).  The sensor
    then reports or not at every step, so the robot's belief reads every report, not
    only the first.  With a law that surely happens, truncated at ``T``, the belief is a
    function of each hypothesis's count of reports before its report was due, and two
    hypotheses whose reports are both due see the same likelihood at every later step:
    the information state is finite, and the information-state product builds it
    (:mod:`mitld_lp.sensing.rules`).  With a law that may never happen (``never > 0``)
    "never" against "happened at ``k``" moves by every report for ever (a random walk in
    the counts of reports and misses): the information state is not finite, and the
    ``sensed`` and ``sensed-constrained`` routes bracket the optimum
    (:mod:`mitld_lp.routes.sensed_never`).  The ``sensed`` and ``sensed-constrained``
    routes build false alarms at a point law that surely happens; ``never``: the caller
    brackets them at a law that may never happen (a point law on both routes; a band,
    its worst or best law on the ``sensed`` route, with constraints its worst law on the
    sensed band constrained route and its best law on the sensed optimistic constrained
    route: each end the band's problem with the sensor blind or informed,
    :mod:`mitld_lp.routes.sensed_never`).  A band
    (``robust``) whose laws surely happen: its worst case (``worst``: alone on the
    ``sensed`` route, :mod:`mitld_lp.routes.sensed_band`; with constraints, ``then`` or
    the trade-off curve on the sensed band constrained route,
    :mod:`mitld_lp.routes.sensed_band_constrained`) is solved as without false alarms
    (the candidates are point-law solves, and the controller's interval chain draws
    every step's report as its point chain does).  Read for its best law (``best``, the
    optimistic sensed routes, constraints or not) it is solved as without false alarms
    too (:mod:`mitld_lp.routes.sensed_optimistic`: the candidates are point-law
    solves, judged on the same interval chain at nature's best corners;
    :mod:`mitld_lp.routes.sensed_optimistic_constrained`: point-law constrained solves,
    each at its own law).  A route that is neither refuses it."""
    head = f"sensors.{event}.false_alarm = {false_alarm:g}: with false alarms the robot's " \
           "belief reads the report of every step"
    if law is not None and float(law.never) > 0.0 and not never:
        return [f"{head}, and with a law that may never happen ({event} never happens with "
                f"probability {float(law.never):.6g}) the belief that {event} never "
                "happens moves with every report for ever, so the information state is "
                "not finite; bracketed with a point law (routes sensed and "
                "sensed-constrained) and with a band (route sensed, its worst or best "
                "law; with constraints or then its worst or best law, route "
                "sensed-constrained), not solved on this route (give false_alarm = 0, or "
                "a law that surely happens)"]
    refused = []
    if robust and not (worst or best):
        refused.append(f"{head}: with a law known only within a band, not solved on this "
                       "route (its worst case is: alone on the sensed route, with bounds on "
                       "other formulas, then or the trade-off curve on the sensed band "
                       "constrained route; its best law, --bands best, on the optimistic "
                       "sensed routes); give the event a point law or false_alarm = 0")
    return refused


def band_refusals(model: Any, head: str, objective: str, constraints: Sequence[Any]
                  ) -> list[str]:
    """Why sensors with a law known only within a band cannot be solved as posed on a
    route that reads laws as points: the worst case over the band is solved for either
    objective without constraints (:mod:`mitld_lp.routes.sensed_band`); with
    constraints or ``then`` by the routes ahead in the precedence list
    (:mod:`mitld_lp.routes.sensed_band_constrained`, bands 'worst';
    :mod:`mitld_lp.routes.sensed_optimistic_constrained`, bands 'best'), so this is
    said only to a route list without them."""
    bands = ", ".join(f"{e} ~ {d}" for e, d in sorted(model.distributions.items())
                      if d.is_ambiguous)
    with_ = f"{head} with a law known only within a band ({bands})"
    if constraints:
        return [f"{with_} and constraints: the sensed-constrained route reads laws as "
                "points; the band is the sensed band constrained route's (bands 'worst') "
                "or the sensed optimistic constrained route's (bands 'best'), which this "
                "list of routes does not hold"]
    return []
