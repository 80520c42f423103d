"""The chunks of the frontier-at-a-time build (:mod:`mitld_lp.sensing.frontier`): the
states of a level expanded together, bounded by their number, by their hypotheses
(a chunk's rows, hence its working arrays, grow with its hypotheses, not its states)
and by the rows their hypotheses are foreseen to make (:class:`RowGauge`)."""

from __future__ import annotations

import numpy as np

__all__ = ["CHUNK", "CHUNK_HYPOTHESES", "CHUNK_ROWS", "RowGauge", "chunk_end"]

CHUNK = 8_192  # the most states expanded together (and CHUNK_HYPOTHESES)
CHUNK_HYPOTHESES = 8_192
"""The most hypotheses in the states of one chunk (:func:`chunk_end`; one state alone
may hold more).  A chunk's rows, some twenty numbers each, are its hypotheses' branches
and successors: on issue 45's sensed case 8,192 states of a late level held some 50,000
hypotheses and made 635,000 rows, whose pages and arrays (200 MB) set the build's peak
at 323 bytes a transition; bounded so, a chunk makes at most some 210,000 rows and the
peak is 130, for the same build time."""
CHUNK_ROWS = 131_072
"""The most rows (decided and undecided, some twenty numbers each, in the compiled
kernel's pages, which the build keeps from level to level) a chunk is foreseen to make,
at the rate of rows a hypothesis of the last chunk (:class:`RowGauge`).  Issue 45's
sensed case made up to 207,978 rows in a chunk of 8,192 hypotheses: those pages and
the level's arrays made of them were the build's peak; the few chunks past this bound
are cut smaller, the others are as they were (the product is the same whatever the
chunks: tests/test_sensed_mem_chunks.py, tests/test_sensed_peak_84.py)."""


class RowGauge:
    """The rows a hypothesis made in the last chunk expanded, as a bound on the next
    chunk's hypotheses (:data:`CHUNK_ROWS`)."""

    def __init__(self) -> None:
        self.rate = 0.0

    def made(self, hypotheses: int, rows: int) -> None:
        """A chunk of ``hypotheses`` made ``rows`` rows."""
        if hypotheses > 0:
            self.rate = rows / hypotheses

    def limit(self) -> int:
        """The most hypotheses of the next chunk."""
        if self.rate * CHUNK_HYPOTHESES <= CHUNK_ROWS:
            return CHUNK_HYPOTHESES
        return max(int(CHUNK_ROWS / self.rate), 1)


def chunk_end(held: np.ndarray, head: int, limit: int | None = None) -> int:
    """The end of the chunk from state ``head`` of a level whose states from ``head`` on
    hold ``held`` hypotheses each: past the first state only while they hold ``limit``
    (:data:`CHUNK_HYPOTHESES` where None) in all, and never past the level's last."""
    total = np.cumsum(held)
    bound = CHUNK_HYPOTHESES if limit is None else limit
    return head + max(int(np.searchsorted(total, bound, side="right")), 1)
