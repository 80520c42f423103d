"""Where the points are solved: in this process, in a local process pool, or on a Dask
distributed cluster.  Each engine yields ``(task, result columns)`` as points finish.

* serial: one point after the other, in this process;
* ``workers=N``: a :class:`concurrent.futures.ProcessPoolExecutor` of ``N`` processes
  (started by the ``forkserver`` method: the command's threads are not forked);
* ``dask=ADDRESS``: each point a task on the Dask scheduler at ``ADDRESS``
  (``dask.distributed``, imported only here), submitted with ``retries`` and gathered
  with ``as_completed``.  A worker that dies takes its running task with it; the
  scheduler runs the task again on another worker (up to its ``allowed-failures``), and
  a task that fails beyond its ``retries`` is recorded with status ``lost``.

An interrupt stops the engine: the pending points are cancelled and leave no row.
"""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterator, Sequence
from typing import Any

from mitld_lp.sweep.rows import LOST, MODEL_ERROR, PointTask, failed, solve_point
from mitld_lp.sweep.spec import SweepError

__all__ = ["serial", "process_pool", "dask_cluster", "check_address"]

Finished = Iterator[tuple[PointTask, dict[str, Any]]]


def serial(tasks: Sequence[PointTask]) -> Finished:
    for task in tasks:
        yield task, solve_point(task)


def process_pool(tasks: Sequence[PointTask], workers: int) -> Finished:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    context = multiprocessing.get_context("forkserver")
    # the server imports the solver stack once; each worker is forked from it
    context.set_forkserver_preload(["mitld_lp.sweep.rows", "mitld_lp.synthesis"])
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=context)
    try:
        futures = {pool.submit(solve_point, task): task for task in tasks}
        for future in as_completed(futures):
            task = futures[future]
            try:
                yield task, future.result()
            except KeyboardInterrupt:  # raised by the point's own code (a [python] world)
                # in its worker: this process's interrupts arrive in the main thread
                yield task, failed(MODEL_ERROR, "the point's own code raised KeyboardInterrupt")
            except Exception as exc:  # noqa: BLE001 - a broken pool loses its points
                yield task, failed(LOST, f"{type(exc).__name__}: {exc}")
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


_ADDRESS = re.compile(
    r"(?:(?:tcp|tls|ucx|ws|wss|inproc)://)?"
    r"(?:[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?|\[[0-9A-Fa-f:.]+\])(?::(\d{1,5}))?/?")


def check_address(address: str) -> str:
    """``address`` if it has the form of a Dask scheduler's address (``tcp://host:8786``,
    ``host:8786``, ``tls://[::1]:8786``); else :class:`SweepError` at once, before
    dask is imported or any connection tried."""
    m = _ADDRESS.fullmatch(address) if isinstance(address, str) else None
    if m is None or (m.group(1) is not None and not 0 < int(m.group(1)) < 65536):
        raise SweepError(f"--dask {address!r}: not the address of a Dask scheduler; give "
                         "tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    return address


def dask_cluster(tasks: Sequence[PointTask], address: str, retries: int) -> Finished:
    check_address(address)
    try:
        from dask.distributed import Client, as_completed
    except ImportError:
        raise SweepError("--dask needs dask.distributed (pip install 'mitld_lp[dask]')") from None
    try:
        client = Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SweepError(f"cannot reach the Dask scheduler at {address}: {exc}") from exc
    run = uuid.uuid4().hex[:8]
    futures: list[Any] = []
    try:
        futures = [client.submit(solve_point, task, key=f"mitld-lp-{run}-{task.index}",
                                 pure=False, retries=retries) for task in tasks]
        by_key = {f.key: t for f, t in zip(futures, tasks, strict=True)}
        for future in as_completed(futures, loop=client.loop):
            task = by_key[future.key]
            try:
                yield task, future.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker and the like
                yield task, failed(LOST, f"{type(exc).__name__}: {exc}")
            future.release()
    finally:
        client.cancel(futures)
        client.close()
