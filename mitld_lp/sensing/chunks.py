"""The chunks of the frontier-at-a-time build (:mod:`mitld_lp.sensing.frontier`): the
states of a level expanded together, bounded by their number and by their hypotheses
(a chunk's rows, hence its working arrays, grow with its hypotheses, not its states)."""

from __future__ import annotations

import numpy as np

__all__ = ["CHUNK", "CHUNK_HYPOTHESES", "CHUNK_SHARE", "CHUNK_LEAST", "chunk_bound",
           "chunk_end"]

CHUNK = 8_192  # the most states expanded together (and CHUNK_HYPOTHESES)
CHUNK_HYPOTHESES = 8_192
"""The most hypotheses in the states of one chunk (:func:`chunk_end`; one state alone
may hold more).  A chunk's rows, some twenty numbers each, are its hypotheses' branches
and successors: on issue 45's sensed case 8,192 states of a late level held some 50,000
hypotheses and made 635,000 rows, whose pages and arrays (200 MB) set the build's peak
at 323 bytes a transition; bounded so, a chunk makes at most some 210,000 rows and the
peak is 130, for the same build time."""
CHUNK_SHARE = 256
"""A chunk's hypotheses are also at most this fraction of those found so far: what the
build keeps grows with the states found, and a chunk's working arrays are then a
bounded share of it, not of the product's final size (:func:`chunk_bound`).  On issue
45's sensed case (52,498 states, 1,080,872 transitions) the build's peak falls from
69 to 54 bytes a transition for some 0.1 s more CPU (0.92 -> 1.02-1.10 s; 1/128 of
them: 53, at 1.1-1.2 s); the false-alarm case of experiments/bench_sensed.py finds
enough hypotheses that its bound stays :data:`CHUNK_HYPOTHESES` (its peak, 70, is not
the chunks')."""
CHUNK_LEAST = 2_048
"""The share's bound is never below this many hypotheses (the first levels' chunks would
be a state or two each, a Python pass apiece)."""


def chunk_bound(found: int) -> int:
    """The most hypotheses in a chunk once ``found`` hypotheses are stored."""
    return min(CHUNK_HYPOTHESES, max(CHUNK_LEAST, found // CHUNK_SHARE))


def chunk_end(held: np.ndarray, head: int, found: int) -> int:
    """The end of the chunk from state ``head`` of a level whose states from ``head`` on
    hold ``held`` hypotheses each, ``found`` hypotheses stored so far: past the first
    state only while they hold :func:`chunk_bound` in all, and never past the level's
    last."""
    total = np.cumsum(held)
    return head + max(int(np.searchsorted(total, chunk_bound(found), side="right")), 1)
