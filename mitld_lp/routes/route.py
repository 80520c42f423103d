"""What a route is: one class per route, in the manner of cvxpy's reduction chain.

A route says which problems are of its kind (:meth:`Route.claims`), why it cannot solve
one as posed (:meth:`Route.refusal`: every reason at once, never raising), builds what
its solver needs (:meth:`Route.build`) and solves it (:meth:`Route.solve`).
:func:`mitld_lp.problem.pose` asks the routes of :data:`mitld_lp.routes.precedence.ROUTES`
in order; the first that claims the problem owns it, and its refusal is the problem's.
Nothing outside the routes names one: a reader asks the route (its capabilities below)
or the answer's part record (:class:`mitld_lp.result.Part`).

A new route is one module with one subclass and one line in the precedence list.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from mitld_lp.problem import Posed
    from mitld_lp.result import Result
    from mitld_lp.routes.stages import Built

__all__ = ["Route"]


class Route:
    """A route (module docs).  ``name``: the answer's ``route`` (the JSON's key, the
    word a refusal uses).  Capabilities, for the readers that would otherwise compare
    names: ``exact`` (an exact answer is given on it, :mod:`mitld_lp.exact`),
    ``takes_constraints`` (the answer carries the constraints' values and a randomised
    policy), ``observation_based`` (the controller acts on what sensors report, not on
    the product's states: the fully observed product, its chain, tree and policy map
    answer another problem), ``optimistic`` (a band is read for its best law when the
    settings ask, ``Settings.bands = "best"``)."""

    name: str = "route"
    exact: bool = False
    takes_constraints: bool = False
    observation_based: bool = False
    optimistic: bool = False

    def claims(self, posed: Posed) -> bool:
        """Whether ``posed`` (its route not yet chosen) is of this route's kind: the
        first of the precedence list to claim a problem owns it."""
        raise NotImplementedError

    def refusal(self, posed: Posed) -> list[str]:
        """Every reason this route does not solve ``posed`` as posed, each naming its
        feature (empty: it does).  Never raises."""
        raise NotImplementedError

    def build(self, posed: Posed, progress: bool | None = None) -> Built:
        """The automaton, STA and product this route's solver works on, under the
        problem's budgets (:mod:`mitld_lp.routes.stages`)."""
        raise NotImplementedError

    def solve(self, posed: Posed, built: Built, *, costs: Mapping[str, float] | None = None,
              seed: int | None = 0) -> Result:
        """The answer on ``built`` (``costs`` / ``seed``: a randomised policy's action
        costs and generator, for the routes that have one)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<route {self.name}>"
