"""The library's defaults, each defined once; every stage and the CLI read them here."""

from __future__ import annotations

__all__ = ["EPSILON", "MAX_STATES", "TOL", "CERTIFY_TOL"]

EPSILON = 0.01
"""Truncation budget shared over the events whose hazard never becomes constant."""

MAX_STATES = 5_000_000
"""Largest product (reachable states) built before refusing with the numbers."""

TOL = 1e-9
"""Accuracy asked of the solvers (LP gap and feasibility, interval-iteration gap)."""

CERTIFY_TOL = 1e-6
"""How far two routes to one value may differ for the answer to count as certified."""
