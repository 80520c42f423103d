"""The routes a posed problem is solved by (robust, constrained, robust
constrained, the trade-off curve) and what they share (the acceptance target,
the constraint records)."""
