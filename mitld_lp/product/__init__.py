"""The product of the game with the STA: a finite MDP, built over reachable states only.

A product state is ``(game state, automaton state, pending events, clock)``.  From it
the robot picks an action ``a``; the environment's events ``E`` of the step are drawn
from the pending events' hazards (:meth:`STA.outcomes`); the game moves to ``s'`` with
probability ``P(s' | s, a, E)``; the automaton reads the label ``L(s') = props(s') | E``.
So the product's transitions are::

    P((s, q, Y, c) --a--> (s', q', Y \\ E, c'))  =  p_STA(E | Y, c) * P(s' | s, a, E)
    with q' = delta(q, props(s') | E) and c' = STA.advance(Y \\ E, c).

At step 0 no event has happened: the initial state is ``(s0, delta(q0, props(s0)), U, 0)``.
Accepting automaton states collapse into one absorbing ``target`` state, rejecting ones
into ``sink``, and outcomes that cross a truncation point into ``truncated``; the three
are kept apart in the MDP's masks, so one build yields both the lower model (truncated
loses) and the upper model (truncated wins).  They are the :class:`Absorbing` members.

The construction (:func:`product`) numbers every factor with integers -- game states,
situations ``(Y, c)``, automaton states -- asks each factor once per distinct question
(the game per (state, action, events), the STA per situation, the automaton per (state,
letter)) and joins the answers for a whole batch of product states at a time in numpy.
A product state is an integer key (:class:`mitld_lp.product.states.KeyCodec`);
``MDP.states`` makes its record (:class:`ProductState`) when asked.  Budgets
(:func:`estimate_size`, states, memory) are checked before the work that would exceed
them.

The modules, one concern each: :mod:`~mitld_lp.product.build` (the breadth-first
construction and the MDP's assembly), :mod:`~mitld_lp.product.table_levels` (a plain
table world's levels in few NumPy calls), :mod:`~mitld_lp.product.layers` (the factors,
each asked once), :mod:`~mitld_lp.product.states` (the key codec and the state
records), :mod:`~mitld_lp.product.budget` (the size estimate and the budgets); the array
kernels they use are in :mod:`mitld_lp.util.arrays`.
"""

from mitld_lp.product.budget import (
    BYTES_PER_STATE,
    BYTES_PER_TRANSITION,
    ProductTooLarge,
    SizeEstimate,
    default_max_memory,
    estimate_size,
)
from mitld_lp.product.build import product, robust_product
from mitld_lp.product.states import Absorbing, ProductState, ProductStates, component_counts

__all__ = [
    "Absorbing",
    "robust_product",
    "BYTES_PER_STATE",
    "BYTES_PER_TRANSITION",
    "SizeEstimate",
    "default_max_memory",
    "estimate_size",
    "ProductState",
    "ProductStates",
    "ProductTooLarge",
    "product",
    "component_counts",
]
