"""The resident size against glibc's heap, stage by stage, and where it reaches each new
high: what part of ``bench_qvbs.py``'s bytes per transition is live arrays and what part
is freed heap left resident (glibc only: ``mallinfo2``, ``malloc_trim``)::

    python experiments/heap_stages.py --model /tmp/models/csma.4-2.some_before.toml
    python experiments/heap_stages.py --model M.toml --trim   # malloc_trim at each boundary

At each entry and exit of a stage (the product, the analysis, the iteration, the LP, the
certificate), in bytes per product transition above the size before ``synthesize``: the
resident size and its peak (``VmHWM``), the heap's size (``arena``), what is in use in it
(``uordblks``) and free in it (``fordblks``), and the large blocks mapped apart
(``hblkhd``).  A thread samples the resident size every half millisecond and, at each new
high (a MiB above the last), records the synthesis's innermost frames of the package:
the last lines are where the peak was reached.  ``--trim`` calls ``malloc_trim(0)`` at
every boundary (the freed heap given back): its peak is what the
stages reach on a heap without the earlier stages' free chunks.  The answer is printed.

Run it from the checkout whose package it measures (``PYTHONPATH=<checkout>``).
"""

from __future__ import annotations

import argparse
import ctypes
import importlib
import sys
import threading
from typing import Any

STAGES = (("mitld_lp.routes.stages", "product", "product"),
          ("mitld_lp.solvers.analysis", "analyse", "analysis"),
          ("mitld_lp.solvers.iteration", "interval_iterations", "iteration"),
          ("mitld_lp.solvers.lp", "solve_lp", "lp"),
          ("mitld_lp.solvers.certify", "certify", "certificate"))
FIELDS = ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks",
          "uordblks", "fordblks", "keepcost")


class _Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in FIELDS]


def _rss() -> int:
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * 4096


def _hwm() -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise OSError("no VmHWM")


def _frames(frame: Any, n: int = 4) -> str:
    where = []
    while frame is not None and len(where) < n:
        name = frame.f_code.co_filename
        if "/mitld_lp/" in name:
            where.append(f"{name.split('/mitld_lp/')[1]}:{frame.f_lineno}"
                         f"({frame.f_code.co_name})")
        frame = frame.f_back
    return " <- ".join(where)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--model", required=True, help="a model file (bench_qvbs writes them)")
    ap.add_argument("--trim", action="store_true", help="malloc_trim(0) at each boundary")
    args = ap.parse_args(argv)
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _Info
    from mitld_lp import load_model, synthesize

    model = load_model(args.model)
    rows: list[tuple[str, int, int, int, int, int, int]] = []

    def show(tag: str) -> None:  # raw bytes now, per transition once the product is known
        if args.trim:
            libc.malloc_trim(0)
        info = libc.mallinfo2()
        rows.append((tag, _rss(), _hwm(), info.arena, info.uordblks, info.fordblks,
                     info.hblkhd))

    def wrap(module: str, attr: str, name: str) -> None:
        mod = importlib.import_module(module)
        orig = getattr(mod, attr)

        def inner(*a: Any, **k: Any) -> Any:
            show("enter " + name)
            try:
                return orig(*a, **k)
            finally:
                show("exit " + name)

        for other in list(sys.modules.values()):  # the callers that imported the name
            if getattr(other, "__name__", "").startswith("mitld_lp") and \
                    getattr(other, attr, None) is orig:
                setattr(other, attr, inner)

    importlib.import_module("mitld_lp.routes.plain")
    for stage in STAGES:
        wrap(*stage)
    main_thread = threading.get_ident()
    done = threading.Event()
    highs: list[tuple[int, str]] = []

    def sample() -> None:
        best = 0
        while not done.wait(0.0005):
            now = _rss()
            if now > best + (1 << 20):  # a MiB above the last
                best = now
                highs.append((now, _frames(sys._current_frames().get(main_thread))))

    with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
        f.write("5")  # the peak from here
    base = _rss()
    show("start")
    watcher = threading.Thread(target=sample, daemon=True)
    watcher.start()
    r = synthesize(model)
    done.set()
    watcher.join()
    show("end")
    n = float(r.mdp.n_transitions)
    print(f"{r.mdp.n_transitions:,} transitions; bytes a transition above the start")
    for tag, rss, hwm, arena, used, free, mapped in rows:
        print(f"{tag:20s} rss {(rss - base) / n:6.1f} peak {(hwm - base) / n:6.1f}"
              f" heap {arena / n:6.1f} in use {used / n:6.1f} free {free / n:6.1f}"
              f" mapped {mapped / n:6.1f}")
    print(f"answer: [{r.lower!r}, {r.upper!r}], certified={r.certified}")
    print("the last new highs of the resident size (bytes a transition, where):")
    for now, where in highs[-8:]:
        print(f"  {(now - base) / n:6.1f}  {where}")


if __name__ == "__main__":
    main()
