"""The ``sensed-reacting`` route (:class:`SensedReactingRoute`): a sensor that misses an
event the world's moves react to (the world's ``event_names``), solved on the
information-state product whose posteriors weigh each hypothesis by its likelihood of
the observed world transitions (:mod:`mitld_lp.sensing.reacting`), then as the
``sensed`` route solves its product (:func:`mitld_lp.routes.sensed_solve.solve_sensed`:
the same certificate, controller and part record, so ``run``, ``export --chain`` and
``export --tree`` read the answer as they read the ``sensed`` route's).

It claims what the ``sensed`` route would (a sensor that misses, no constraints) when
the world reacts to a sensed event; a law known within a band is refused by name (the
band's solvers, :mod:`mitld_lp.routes.sensed_band`, are not wired to this product), as
are false alarms (this product reads each sensor's first report only).  Constraints or
``then`` with such a world are the ``sensed-constrained`` route's, on the same
product."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from mitld_lp.routes.sensed import SensedRoute, reacting_false_alarm_refusals
from mitld_lp.sensing.sensors import partial, reacting_events

if TYPE_CHECKING:
    from mitld_lp.problem import Posed
    from mitld_lp.routes.stages import Built

__all__ = ["SensedReactingRoute"]


class SensedReactingRoute(SensedRoute):
    """A sensor that misses an event the world's moves react to (module docs): every
    task class, either objective, point laws, no constraints."""

    name = "sensed-reacting"

    def claims(self, posed: Posed) -> bool:
        return super().claims(posed) and bool(
            reacting_events(posed.model.game, partial(posed.model.sensors)))

    def refusal(self, posed: Posed) -> list[str]:
        model = posed.problem.model
        sensors = partial(model.sensors)
        refused = reacting_false_alarm_refusals(sensors)
        if posed.robust:
            reacts = ", ".join(sorted(reacting_events(model.game, sensors)))
            bands = ", ".join(f"{e} ~ {d}" for e, d in sorted(model.distributions.items())
                              if d.is_ambiguous)
            refused.append(
                f"sensors on events the world's moves react to ({reacts}, event_names) with "
                f"a law known only within a band ({bands}): the worst case over the band "
                "with a world whose moves reveal the sensed event is not solved; give the "
                "events point laws")
        return refused

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        """The task's automaton (a minimum posed as the ``sensed`` route poses it), then
        the information-state product of the reacting world, under the problem's
        budgets."""
        from mitld_lp.automata.translate import to_dta
        from mitld_lp.routes.stages import Built, reaching
        from mitld_lp.sensing.reacting import reacting_product

        model, s = posed.model, posed.settings
        assert s.max_states is not None and s.max_automaton_states is not None  # resolved
        t0 = time.perf_counter()
        dta = to_dta(model.spec, max_states=min(s.max_states, s.max_automaton_states))
        direct = posed.minimise and reaching(dta)  # no band here (refused)
        if posed.minimise and not direct:
            dta = dta.complement()
        t1 = time.perf_counter()
        belief = reacting_product(model.game, dta, model.distributions,
                                  partial(model.sensors),
                                  model.epsilon if s.epsilon is None else s.epsilon,
                                  clock_reduction=s.clock_reduction,
                                  truncation=s.truncation_map, max_states=s.max_states,
                                  max_memory=s.max_memory, progress=progress,
                                  name=model.name)
        return Built(dta, belief.sta, belief.mdp,
                     {"automaton": t1 - t0, "product": time.perf_counter() - t1},
                     belief=belief, sense="min" if direct else "max")
