"""The routes a posed problem is solved by: what a route is (:mod:`.route`), the order
:func:`mitld_lp.synthesis.pose` asks them in (:mod:`.precedence`), the plain, robust,
constrained and robust constrained routes (the sensed one is in :mod:`mitld_lp.sensing`),
the stages they build from, the trade-off curve, and what they share (the acceptance
target, the constraint records)."""
