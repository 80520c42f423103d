"""The routes, in the order :func:`mitld_lp.synthesis.pose` asks them: the first that
claims a problem owns it (:class:`mitld_lp.routes.route.Route`).

A new route is one module with one :class:`~mitld_lp.routes.route.Route` subclass and
one line here, before the routes whose problems it takes over.
"""

from __future__ import annotations

from mitld_lp.routes.constrained import ConstrainedRoute
from mitld_lp.routes.plain import PlainRoute
from mitld_lp.routes.robust import RobustRoute
from mitld_lp.routes.robust_constrained import RobustConstrainedRoute
from mitld_lp.routes.route import Route
from mitld_lp.routes.sensed import SensedRoute
from mitld_lp.routes.sensed_band_constrained import SensedBandConstrainedRoute
from mitld_lp.routes.sensed_constrained import SensedConstrainedRoute
from mitld_lp.routes.sensed_optimistic import SensedOptimisticRoute
from mitld_lp.routes.sensed_optimistic_constrained import SensedOptimisticConstrainedRoute
from mitld_lp.routes.sensed_reacting import SensedReactingRoute

__all__ = ["ROUTES", "LP"]

#: Every route, in precedence.
ROUTES: list[Route] = [
    SensedOptimisticConstrainedRoute(),  # ... with a band read for its best law
    SensedBandConstrainedRoute(),  # constraints or then with such a sensor and a band
    SensedConstrainedRoute(),  # constraints or then with such a sensor
    SensedReactingRoute(),  # such a sensor on an event the world's moves react to
    SensedOptimisticRoute(),  # such a sensor and a band read for its best law
    SensedRoute(),  # a sensor that misses its event: what the robot observes
    RobustConstrainedRoute(),  # constraints and a band
    ConstrainedRoute(),  # constraints or then, point laws
    RobustRoute(),  # a band
    PlainRoute(),  # point laws, no constraints, perfect sensors
]

#: The constrained LP's routes, claiming a problem without constraints too (the
#: trade-off curve's end points, :func:`mitld_lp.synthesis.synthesize_constrained`).
LP: tuple[Route, ...] = (SensedOptimisticConstrainedRoute(every=True),
                         SensedBandConstrainedRoute(every=True),
                         SensedConstrainedRoute(every=True),
                         RobustConstrainedRoute(every=True),
                         ConstrainedRoute(every=True))
