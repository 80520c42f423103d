"""What a block's sweeps read of their own progress between two chunks of sweeps
(:func:`mitld_lp.solvers.iteration._block_sweeps`): the sweeps its gap still needs at
its recent rate (:func:`needed`, which the early jump and the policy jump's forecasts
read too), and the guesses turned off once the gap is about to close (:func:`close_out`).
"""

from __future__ import annotations

import numpy as np

from mitld_lp.solvers.kernels import Prepared, watch_again

__all__ = ["PLAIN_WITHIN", "close_out", "needed"]

PLAIN_WITHIN = 16
"""A compiled block whose gap, shrinking as it did over the last chunk of sweeps, is
forecast to close within this many sweeps is swept on plainly (:func:`close_out`)."""


def needed(seen: list[tuple[int, float]], start: int, window: int) -> float | None:
    """The sweeps a block's gap (over its threshold, read after each chunk of sweeps:
    ``seen``) still needs if it kept shrinking at the rate of the last ``window``
    sweeps (``inf`` if it does not shrink); ``None`` before ``start`` sweeps."""
    done, over = seen[-1]
    if done < start:
        return None
    then = next(((d, g) for d, g in reversed(seen) if d <= done - window), None)
    if then is None or then[1] <= 0.0:
        return None
    rate = (over / then[1]) ** (1.0 / (done - then[0]))  # per sweep
    if rate >= 1.0:
        return float("inf")
    return float(np.log(1.0 / over) / np.log(rate))


def close_out(prep: Prepared, seen: list[tuple[int, float]], chunk: int) -> None:
    """Between two chunks (of ``chunk`` sweeps) of a compiled block's sweeps: where the
    gap is forecast (:func:`needed`, from its rate over the last chunk) to close within
    :data:`PLAIN_WITHIN` sweeps, the kernel stops watching for guesses (``track[0]`` -1:
    plain sweeps, the bounds' changes not tracked) while it is between guesses (never
    during a verification); where a block so closed is not closed after the next chunk,
    it watches again from the start (:func:`~mitld_lp.solvers.kernels.watch_again`: its
    ratios read afresh).

    A plain sweep is the same sound update as a watched one, and costs less: on QVBS
    ``zeroconf`` 1000-4 ``correct_min``'s block (213,268 states) the guesses save no
    sweep (42 either way) and its last ten sweeps verified a guess that failed, each
    reading the guesses beside the bounds; its sweeps without guesses took about 0.8 of
    the CPU of those with them (``docs/results.md``, iter-78).  Which sweeps are watched
    changes only when a guess can be made, never the stop test (the kernel's own)."""
    track = prep.track
    if track is None or prep.guess is None:
        return
    ahead = needed(seen, chunk, chunk)
    soon = ahead is not None and ahead <= PLAIN_WITHIN
    if track[0] == 0.0 and soon:
        track[0] = -1.0
        prep.closing = True
    elif prep.closing and track[0] == -1.0 and not soon:
        watch_again(track, prep.guess.shape[1])
        prep.closing = False
