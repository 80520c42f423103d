"""The ``sensed-reacting`` route (:class:`SensedReactingRoute`): a sensor that misses an
event the world's moves react to (the world's ``event_names``), solved on the
information-state product whose posteriors weigh each hypothesis by its likelihood of
the observed world transitions (:mod:`mitld_lp.sensing.reacting`), then as the
``sensed`` route solves its product (:func:`mitld_lp.routes.sensed_solve.solve_sensed`:
the same certificate, controller and part record, so ``run``, ``export --chain`` and
``export --tree`` read the answer as they read the ``sensed`` route's).

It claims what the ``sensed`` route would (a sensor that misses, no constraints) when
the world reacts to a sensed event.  A law known within a band is solved by the band's
solvers of the ``sensed`` route on this route's product: its worst law
(:func:`mitld_lp.routes.sensed_band.solve_sensed_band`) and, with ``bands = "best"``,
its best (:func:`mitld_lp.routes.sensed_optimistic_solve.solve_sensed_optimistic`).
Their candidates are this route's optima at the band's middle law and ends (each
candidate's product built by this route, :func:`mitld_lp.routes.sensed_band.
sensed_candidate`), each judged on its interval chain over the truth and its memory,
which moves the world on the true events, the sensed ones included
(:mod:`mitld_lp.running.sensed_chain`): what the world's reaction tells the robot is in
the candidates' posteriors, and its controller's worst (best) case is read on the real
dynamics.  False alarms are read at every step (the product weighs each hypothesis by
every report or silence) where the law surely happens.  With a law that may never happen
the belief that the event never happens moves with every report for ever, and the
optimum is bracketed as on a world that ignores its events
(:mod:`mitld_lp.routes.sensed_never`), each end this route's solve: the product built
with that sensor blind (only the world's moves tell the robot of the event), its
reports dropped by the controller returned (:func:`~mitld_lp.routes.sensed_never.
dropping`), and a sensor without false alarms at least as informative, whose reports
give the posed ones by a garbling that does not touch the world's moves (so every
posed controller is one of its, and the blind one, reading the same world moves, one of
the posed problem's).  Under a band (its worst or best law) both ends are the band's
solves on those products (:func:`~mitld_lp.routes.sensed_never.solve_never_band`).
Constraints or ``then`` with such a world are the ``sensed-constrained``
route's, on the same product (with a band, :mod:`mitld_lp.routes.sensed_band_constrained`
for its worst law, :mod:`mitld_lp.routes.sensed_optimistic_constrained` for its best)."""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import TYPE_CHECKING

from mitld_lp.routes.sensed import SensedRoute, task_automaton
from mitld_lp.sensing.sensors import partial, reacting_events

if TYPE_CHECKING:
    from mitld_lp.problem import Posed
    from mitld_lp.result import Result
    from mitld_lp.routes.stages import Built

__all__ = ["SensedReactingRoute"]


class SensedReactingRoute(SensedRoute):
    """A sensor that misses an event the world's moves react to (module docs): every
    task class, either objective, point laws or a band (its worst law, or its best
    with ``bands = "best"``), false alarms (bracketed where the law may never happen),
    no constraints."""

    name = "sensed-reacting"
    optimistic = True  # a band's best law too (module docs)

    def claims(self, posed: Posed) -> bool:
        return super().claims(posed) and bool(
            reacting_events(posed.model.game, partial(posed.model.sensors)))

    def refusal(self, posed: Posed) -> list[str]:
        return []  # every problem it claims: false alarms at a never law bracketed

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        """The task's automaton (a minimum posed as the ``sensed`` route poses it), then
        the information-state product of the reacting world, under the problem's
        budgets; the sensors :func:`~mitld_lp.routes.sensed_never.never_alarms` names
        built blind, their reports dropped (module docs)."""
        from mitld_lp.routes.sensed_never import blind_model, dropping, never_alarms
        from mitld_lp.routes.stages import Built
        from mitld_lp.sensing.reacting import reacting_product

        model, s = posed.model, posed.settings
        blind = never_alarms(model)
        if blind:
            model = blind_model(model)
        t0 = time.perf_counter()
        dta, direct = task_automaton(posed)  # a minimum as the sensed route poses it
        t1 = time.perf_counter()
        belief = reacting_product(model.game, dta, model.distributions,
                                  partial(model.sensors),
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
        """As the ``sensed`` route solves its product; a band read for its best law by
        the optimistic band solve; false alarms at a law that may never happen bracketed
        with the informed end on this route (module docs)."""
        from mitld_lp.routes.sensed_never import never_alarms, solve_never, solve_never_band

        if not never_alarms(posed.model):
            return self._solve(posed, built)
        # the informed end: this route while its sensor is not perfect (d' < 1) or
        # another sensed event the world reacts to is left, else the one that claims it
        from mitld_lp.routes.plain import PlainRoute
        from mitld_lp.routes.robust import RobustRoute
        from mitld_lp.routes.sensed_optimistic import SensedOptimisticRoute

        if posed.robust:
            return solve_never_band(posed, self._solve(posed, built), (
                SensedReactingRoute(), SensedOptimisticRoute(), SensedRoute(), RobustRoute()))
        return solve_never(posed, self._solve(posed, built),
                           (SensedReactingRoute(), SensedRoute(), PlainRoute()))

    def _solve(self, posed: Posed, built: Built) -> Result:
        """The problem on the product ``built`` (blind where :meth:`build` made it so):
        a band's best law by the optimistic band solve, else as the ``sensed`` route."""
        if posed.robust and posed.settings.bands == "best":
            from mitld_lp.routes.sensed_optimistic_solve import solve_sensed_optimistic

            return solve_sensed_optimistic(posed, built)
        return super()._solve(posed, built)
