"""The chunks of the frontier-at-a-time build (:mod:`mitld_lp.sensing.frontier`): the
states of a level expanded together, bounded by their number and by their hypotheses
(a chunk's rows, hence its working arrays, grow with its hypotheses, not its states)."""

from __future__ import annotations

import numpy as np

__all__ = ["CHUNK", "CHUNK_HYPOTHESES", "chunk_end"]

CHUNK = 8_192  # the most states expanded together (and CHUNK_HYPOTHESES)
CHUNK_HYPOTHESES = 8_192
"""The most hypotheses in the states of one chunk (:func:`chunk_end`; one state alone
may hold more).  A chunk's rows, some twenty numbers each, are its hypotheses' branches
and successors: on issue 45's sensed case 8,192 states of a late level held some 50,000
hypotheses and made 635,000 rows, whose pages and arrays (200 MB) set the build's peak
at 323 bytes a transition; bounded so, a chunk makes at most some 210,000 rows and the
peak is 130, for the same build time."""


def chunk_end(held: np.ndarray, head: int) -> int:
    """The end of the chunk from state ``head`` of a level whose states from ``head`` on
    hold ``held`` hypotheses each: past the first state only while they hold
    :data:`CHUNK_HYPOTHESES` in all, and never past the level's last."""
    total = np.cumsum(held)
    return head + max(int(np.searchsorted(total, CHUNK_HYPOTHESES, side="right")), 1)
