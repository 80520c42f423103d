"""The routes, in the order :func:`mitld_lp.synthesis.pose` asks them: the first that
claims a problem owns it (:class:`mitld_lp.routes.route.Route`).

A new route is one module with one :class:`~mitld_lp.routes.route.Route` subclass and
one line here, before the routes whose problems it takes over.

Every route but the plain one is listed by its module and class (:class:`Later`) and
imported when a problem the plain route does not claim is asked of it: each claims only
problems with a band, constraints or a sensor that misses, which the plain route never
claims, so a plain problem (the bundled case) is posed without importing them (their
modules and solvers, 0.01-0.02 s of a 0.3 s command; tests/test_imports.py).
"""

from __future__ import annotations

import importlib
from typing import Any

from mitld_lp.routes.plain import PlainRoute
from mitld_lp.routes.route import Route

__all__ = ["ROUTES", "LP", "Later"]


class Later:
    """The route ``cls`` of ``mitld_lp.routes.<module>`` (made with ``options``), its
    module imported on first use, and otherwise that route (every attribute and method
    is the route's own).  Without options it claims no problem the plain route claims
    (module docs), which is answered without the import."""

    def __init__(self, module: str, cls: str, **options: Any) -> None:
        self._where, self._options, self._route = (module, cls), options, None

    def route(self) -> Route:
        """The route itself (its module imported the first time)."""
        if self._route is None:
            module, cls = self._where
            made = getattr(importlib.import_module(f"mitld_lp.routes.{module}"), cls)
            self._route = made(**self._options)
        return self._route

    def claims(self, posed: Any) -> bool:
        if not self._options and _PLAIN.claims(posed):
            return False
        return self.route().claims(posed)

    def __getattr__(self, name: str) -> Any:  # refusal, build, solve, name, exact...
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.route(), name)

    def __repr__(self) -> str:
        return repr(self.route())


_PLAIN = PlainRoute()

#: Every route, in precedence.
ROUTES: list[Any] = [
    # ... with a band read for its best law
    Later("sensed_optimistic_constrained", "SensedOptimisticConstrainedRoute"),
    # constraints or then with such a sensor and a band
    Later("sensed_band_constrained", "SensedBandConstrainedRoute"),
    Later("sensed_constrained", "SensedConstrainedRoute"),  # constraints or then with such a sensor
    # such a sensor on an event the world's moves react to
    Later("sensed_reacting", "SensedReactingRoute"),
    # such a sensor and a band read for its best law
    Later("sensed_optimistic", "SensedOptimisticRoute"),
    Later("sensed", "SensedRoute"),  # a sensor that misses its event: what the robot observes
    Later("robust_constrained", "RobustConstrainedRoute"),  # constraints and a band
    Later("constrained", "ConstrainedRoute"),  # constraints or then, point laws
    Later("robust", "RobustRoute"),  # a band
    Later("horizon", "HorizonRoute", first=True),  # F[0,k] on a large explored world
    _PLAIN,  # point laws, no constraints, perfect sensors
]

#: The constrained LP's routes, claiming a problem without constraints too (the
#: trade-off curve's end points, :func:`mitld_lp.synthesis.synthesize_constrained`).
LP: tuple[Any, ...] = (
    Later("sensed_optimistic_constrained", "SensedOptimisticConstrainedRoute", every=True),
    Later("sensed_band_constrained", "SensedBandConstrainedRoute", every=True),
    Later("sensed_constrained", "SensedConstrainedRoute", every=True),
    Later("robust_constrained", "RobustConstrainedRoute", every=True),
    Later("constrained", "ConstrainedRoute", every=True))
