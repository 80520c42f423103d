"""What a route is: one class per route, in the manner of cvxpy's reduction chain.

A route says which problems are of its kind (:meth:`Route.claims`), why it cannot solve
one as posed (:meth:`Route.refusal`: every reason at once, never raising), builds what
its solver needs (:meth:`Route.build`) and solves it (:meth:`Route.solve`).
:func:`mitld_lp.synthesis.pose` asks the routes of :data:`mitld_lp.routes.precedence.ROUTES`
in order; the first that claims the problem owns it, and its refusal is the problem's.
Nothing outside the routes names one: a reader asks the route (its capabilities below)
or the answer's part record (:class:`mitld_lp.result.Part`).

A new route is one module with one subclass and one line in the precedence list.  The
base class stands with the posed problem (:mod:`mitld_lp.problem`), which every route
takes and which names its owner.
"""

from __future__ import annotations

from mitld_lp.problem import Route

__all__ = ["Route"]
