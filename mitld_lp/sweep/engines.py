"""Where the points are solved: in this process or in a local process pool.  Each
engine yields ``(task, result columns)`` as points finish.

* serial: one point after the other, in this process;
* ``workers=N``: a :class:`concurrent.futures.ProcessPoolExecutor` of ``N`` processes
  (started by the ``forkserver`` method: the command's threads are not forked);

An interrupt stops the engine: the pending points are cancelled and leave no row.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

from mitld_lp.sweep.rows import LOST, PointTask, failed, solve_point

__all__ = ["serial", "process_pool"]

Finished = Iterator[tuple[PointTask, dict[str, Any]]]


def serial(tasks: Sequence[PointTask]) -> Finished:
    for task in tasks:
        yield task, solve_point(task)


def process_pool(tasks: Sequence[PointTask], workers: int) -> Finished:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    pool = ProcessPoolExecutor(max_workers=workers,
                               mp_context=multiprocessing.get_context("forkserver"))
    try:
        futures = {pool.submit(solve_point, task): task for task in tasks}
        for future in as_completed(futures):
            task = futures[future]
            try:
                yield task, future.result()
            except Exception as exc:  # noqa: BLE001 - a broken pool loses its points
                yield task, failed(LOST, f"{type(exc).__name__}: {exc}")
    finally:
        pool.shutdown(wait=False, cancel_futures=True)
