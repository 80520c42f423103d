"""Sensed events whose law is known only within a band, the band read for its best law
(``Settings.bands = "best"``, PRISM's ``Pmaxmax``, Storm's cooperative resolution): the
optimum over the policies that act on observations of the best case over the band,
bracketed soundly, certified where the bracket closes.

What is solved (docs/semantics.md, "Laws known roughly"): at every step nature picks
each pending band event's hazard inside its band at the true clock, seeing everything
(the band's semantics of the robust route), here on the robot's side; the robot sees
only what its sensors report.  The answer is ``sup`` over observation-based policies of
``sup`` over nature's choices of the task's probability.

``lower``: the best case of one concrete controller.  The candidates are the sensed
optimum (:mod:`mitld_lp.routes.sensed_solve`) at the band's middle law, with every band
at its low end and with every band at its high end
(:func:`mitld_lp.routes.sensed_band.end_laws`), as the worst-case route tries them; each
one's best case is read on its interval chain over the truth and its memory
(:mod:`mitld_lp.running.sensed_optimistic_chain`): nature's best corners, fixed, make a
plain chain whose probability of ``accept``, from below, is a sound lower bound.  The
best candidate is returned, with that chain (``export --chain``: Storm's ``P=? [F
"accept"]`` on it is at least ``lower``).  A sensor with false alarms (a band whose laws
surely happen) changes no step, as on the worst-case route: each candidate is the
point-law optimum with false alarms, and its interval chain draws every step's report
(:mod:`mitld_lp.running.sensed_chain`), so nature's best corners are read on the runs
the controller meets (a band that may never happen is bracketed:
:func:`mitld_lp.routes.sensed_never.solve_never_band`).

``upper``: the fully observed cooperative optimum's ``upper`` (the robust route with
the bands read for their best law, the sensors read as perfect): a policy that acts on
observations is one that sees everything, so none does better.  A tighter bound from an
(action, corner) optimum on the information-state product is not sound here: there
nature's corner would depend on what the robot knows only, while in the band's semantics
it sees the truth (which hypothesis holds), so such an optimum may fall below the one
posed.  Where the sensor's misses cost the robot something the bracket stays open,
both ends sound, and the check ``best case over the band`` says the gap; certified when
``upper - lower``, less the truncation's part (the controller's best case with the runs
past a truncation point counted won, above ``lower``: reported apart in ``width`` as
every route's), is within the precision relative to ``lower``.

``objective = "min"``: the complement is maximised, nature helping the robot (the
sensed route builds the complement's automaton under a band), each bound read back:
``upper`` is the returned controller's best case (the task's probability at nature's
chosen law is at most it), ``lower`` the sound bound, ``complement`` the complement's
bracket; the exported chain is the complement's (``accept`` marks the runs that fail the
task), Storm's ``P=?`` of it is at least ``1 - upper``.

Constraints and ``then`` with such a sensor and ``bands = "best"``:
:mod:`mitld_lp.routes.sensed_optimistic_constrained`.

The route (:class:`SensedOptimisticRoute`) is here; the solve in
:mod:`mitld_lp.routes.sensed_optimistic_solve`, imported when such a problem is solved
(the information-state product's modules are not a plain solve's).
"""

from __future__ import annotations

from mitld_lp.problem import Posed
from mitld_lp.result import Result
from mitld_lp.routes.sensed import SensedRoute
from mitld_lp.routes.stages import Built
from mitld_lp.sensing.sensors import partial

__all__ = ["SensedOptimisticRoute"]


class SensedOptimisticRoute(SensedRoute):
    """A sensor that misses its event (or gives false alarms, at a band whose laws
    surely happen) and a law known only within a band read for its best law (``bands =
    "best"``), no constraints: either objective, every task class the sensed route
    takes (module docs)."""

    optimistic = True

    def claims(self, posed: Posed) -> bool:
        return (bool(partial(posed.model.sensors)) and posed.robust
                and posed.settings.bands == "best" and not posed.problem.constrained)

    def _solve(self, posed: Posed, built: Built) -> Result:
        """The band's best law on the product ``built`` (blind for the sensors
        :func:`mitld_lp.routes.sensed_never.never_alarms` names, whose bracket
        :meth:`SensedRoute.solve` makes)."""
        from mitld_lp.routes.sensed_optimistic_solve import solve_sensed_optimistic

        return solve_sensed_optimistic(posed, built)
