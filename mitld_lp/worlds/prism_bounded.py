"""Run Storm's exploration within a memory budget: in a child process whose address
space is capped, so that a program whose reachable part is larger than the budget stops
when the budget is spent, not when the machine's memory is.

Storm explores a PRISM program without a state limit, and the product of the variables'
ranges (:class:`mitld_lp.worlds.prism_program.SizeBound`) is no estimate of the reachable
part (zeroconf: 670 reachable states, 1.8e14 valuations).  When that bound already fits
the budget the build runs in this process; otherwise :func:`run_capped` forks, caps the
child's address space (``RLIMIT_AS``) at what it uses now plus the budget, builds and
copies the model there, and sends the arrays back.  A child that runs out of its cap is
a budget stop (:class:`mitld_lp.worlds.prism.PrismTooLarge` in the caller), whatever
Storm was doing when its allocation failed.

The result goes back pickled with its arrays out of band (pickle protocol 5): the child
writes a short header (the pickle without the arrays' bytes and each array's size) and
then each array's own memory to the pipe, and the parent reads each array's bytes into
a buffer of its size, which the unpickled array then uses.  A pickle with the arrays in
it, collected in chunks and joined, copied the model's arrays four times (arrays of
csma 4-2's sizes, 35 MB: 0.116 s of CPU over both processes; 0.040 s out of band,
``experiments/capped_transfer.py``).

Without ``os.fork`` or ``RLIMIT_AS`` (not Linux or macOS) the work runs in this process.
"""

from __future__ import annotations

import os
import pickle
import signal
import struct
from collections.abc import Callable
from typing import Any, TypeVar

__all__ = ["run_capped", "OutOfBudget", "can_cap"]

T = TypeVar("T")

HEADROOM = 96 << 20
"""Bytes added to the budget in the child: Storm's and Python's allocations that do not
grow with the model (the parse, the export's buffers)."""


class OutOfBudget(Exception):
    """The capped child ran out of its address space (``detail`` says how it ended)."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


def can_cap() -> bool:
    """Whether this platform can run a capped child (``os.fork`` and ``RLIMIT_AS``)."""
    try:
        import resource
    except ImportError:
        return False
    return hasattr(os, "fork") and hasattr(resource, "RLIMIT_AS")


def _address_space() -> int:
    """This process's virtual size in bytes (``/proc/self/statm``; 0 if unknown)."""
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return 0


def _child(work: Callable[[], Any], cap: int, out: int) -> None:  # pragma: no cover - forked
    import resource

    try:
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        _, hard = resource.getrlimit(resource.RLIMIT_AS)
        if cap < 1 << 62:  # beyond, no cap: the budget is larger than any address space
            limit = cap if hard == resource.RLIM_INFINITY else min(cap, hard)
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
        result: tuple[Any, ...] = ("ok", work())
    except MemoryError:
        result = ("memory", "an allocation failed")
    except BaseException as exc:  # noqa: BLE001 - every outcome goes back to the parent
        result = ("raised", exc)
    try:
        parts = _parts(result)
    except MemoryError:
        parts = _parts(("memory", "the copy of the model did not fit"))
    except Exception as exc:  # noqa: BLE001 - an exception that does not pickle
        parts = _parts(("raised", RuntimeError(f"{type(exc).__name__}: {exc}")))
    for part in parts:
        view = memoryview(part).cast("B")
        while view:
            view = view[os.write(out, view) :]
    os.close(out)


def _parts(result: Any) -> list[Any]:
    """What the child writes: the sizes (of the pickle and of each out-of-band buffer,
    ``<Q`` each, after their count), the pickle, then each buffer's own memory."""
    buffers: list[pickle.PickleBuffer] = []
    head = pickle.dumps(result, protocol=5, buffer_callback=buffers.append)
    raw = [b.raw() for b in buffers]
    sizes = struct.pack(f"<QQ{len(raw)}Q", len(head), len(raw), *(r.nbytes for r in raw))
    return [sizes, head, *raw]


def _read_exactly(fd: int, n: int) -> bytearray:
    """``n`` bytes from ``fd`` into a buffer of that size; EOFError if it ends first."""
    out = bytearray(n)
    view = memoryview(out)
    got = 0
    while got < n:
        k = os.readv(fd, [view[got:]])
        if k == 0:
            raise EOFError
        got += k
    return out


def _receive(fd: int) -> Any:
    """The child's result from ``fd`` (:func:`_parts`): its arrays use the buffers read."""
    n_head, n_buffers = struct.unpack("<QQ", _read_exactly(fd, 16))
    sizes = struct.unpack(f"<{n_buffers}Q", _read_exactly(fd, 8 * n_buffers))
    head = _read_exactly(fd, n_head)
    buffers = [_read_exactly(fd, size) for size in sizes]
    return pickle.loads(head, buffers=buffers)


def run_capped(work: Callable[[], T], budget: int) -> T:
    """``work()`` in a child process that may use ``budget`` more bytes of address space
    than this process uses now; its result (pickled, from our own child) or exception.

    Raises :class:`OutOfBudget` when the child runs out of memory or dies."""
    cap = _address_space() + budget + HEADROOM
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 0
        try:
            os.close(read)
            _child(work, cap, write)
        except BaseException:  # noqa: BLE001 - nothing may escape a forked child
            code = 1
        os._exit(code)
    os.close(write)
    received: Any = None
    try:
        received = _receive(read)
    except EOFError:  # the child ended before it had sent its result
        pass
    except BaseException:  # an interrupt or a time limit here: the child stops too
        os.kill(pid, signal.SIGKILL)
        raise
    finally:
        os.close(read)
        _, status = os.waitpid(pid, 0)
    if received is None:
        if os.WIFSIGNALED(status):
            name = signal.Signals(os.WTERMSIG(status)).name
            raise OutOfBudget(f"Storm was stopped by {name} at its memory cap")
        raise OutOfBudget("Storm stopped at its memory cap")
    kind, value = received
    if kind == "ok":
        return value  # type: ignore[no-any-return]
    if kind == "memory":
        raise OutOfBudget(value)
    raise value
