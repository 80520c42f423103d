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
from collections.abc import Generator, Sequence
from typing import Any

from mitld_lp.sweep.rows import LOST, MODEL_ERROR, PointTask, failed, solve_point
from mitld_lp.sweep.spec import SweepError

__all__ = ["serial", "process_pool", "dask_cluster", "check_address", "connect"]

Finished = Generator[tuple[PointTask, dict[str, Any]], None, None]


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


_SCHEMES = ("tcp", "tls", "ucx", "ws", "wss")
"""The protocols of a Dask scheduler's address that another process can reach."""

_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9_-]{0,61}[A-Za-z0-9])?")
"""One label of a host name (RFC 1123; the underscore some resolvers accept)."""


def check_address(address: str) -> str:
    """``address`` if it is the address of a Dask scheduler another process can reach:
    ``[SCHEME://]HOST:PORT`` (``tcp://host:8786``, ``host:8786``, ``tls://[::1]:8786``;
    SCHEME one of :data:`_SCHEMES`, ``tcp`` when absent), HOST a name, an IPv4 address
    or an IPv6 address in brackets, PORT in 1..65535.  Else :class:`SweepError` saying
    what is wrong, at once, before dask is imported or any connection tried."""
    why = _address_fault(address) if isinstance(address, str) else "not text"
    if why is not None:
        raise SweepError(f"--dask {address!r}: not the address of a Dask scheduler ({why}); "
                         "give tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786")
    return address


def _address_fault(address: str) -> str | None:
    """Why ``address`` is no scheduler's address (:func:`check_address`), or None."""
    import ipaddress

    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address
    elif scheme not in _SCHEMES:  # Dask knows them in lower case only
        return f"the protocol {scheme!r} is none of {', '.join(_SCHEMES)}"
    rest = rest.removesuffix("/")
    if rest.startswith("["):
        host, bracket, port = rest[1:].partition("]")
        if not bracket:
            return "an IPv6 address without its closing ']'"
        if not port.startswith(":"):
            return "no port: the address ends without ':PORT'" if not port else \
                f"{port!r} after the IPv6 address, not ':PORT'"
        port = port[1:]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            return f"{host!r} is no IPv6 address"
    else:
        host, colon, port = rest.rpartition(":")
        if not colon:
            return "no port: the address ends without ':PORT'"
        if ":" in host:
            return "an IPv6 address must be written in brackets, [ADDRESS]:PORT"
        if not host:
            return "no host before ':PORT'"
        if re.fullmatch(r"[0-9.]+", host):
            try:
                ipaddress.IPv4Address(host)
            except ValueError:
                return f"{host!r} is no IPv4 address"
        elif len(host) > 253 or not all(_LABEL.fullmatch(x) for x in host.split(".")):
            return f"{host!r} is no host name"
    if not port.isascii() or not port.isdigit():
        return "no port: the address ends without ':PORT'" if not port else \
            f"the port {port!r} is not a number"
    if not 0 < int(port) < 65536:
        return f"the port {int(port)} is outside 1..65535"
    return None


def connect(address: str) -> Any:
    """A ``dask.distributed`` client of the scheduler at ``address`` (checked first by
    :func:`check_address`); :class:`SweepError` when dask is missing or the scheduler
    does not answer within 10 s."""
    check_address(address)
    try:
        from dask.distributed import Client
    except ImportError:
        raise SweepError("--dask needs dask.distributed (pip install 'mitld_lp[dask]')") from None
    try:
        return Client(address, timeout="10s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SweepError(f"cannot reach the Dask scheduler at {address}: {exc}") from exc


def dask_cluster(tasks: Sequence[PointTask], client: Any, retries: int) -> Finished:
    """The points as tasks of ``client`` (:func:`connect`); the caller closes it."""
    from dask.distributed import as_completed

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
