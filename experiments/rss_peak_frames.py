"""Where one synthesis's resident size is highest, sampled, with no tracer on.

A thread reads the resident size (``/proc/self/statm``) every half millisecond and, at
each new high, the main thread's innermost frames in the package; printed: the peak in
bytes per product transition above the size before ``synthesize`` (as
``bench_qvbs.py`` counts it: its start-up and preload first, the model loaded before),
the bracket, and those frames.  ``--trim-at NAME``: also, at each return of a package
function of that name, the resident size before and after ``malloc_trim(0)`` (the free
heap pages there, Linux with glibc)::

    python experiments/rss_peak_frames.py sensed
    python experiments/rss_peak_frames.py model.toml --trim-at everywhere

(a model file as ``bench_qvbs.py`` writes them, or ``sensed``: ``bench_sensed``'s case 0).
Run it with the checkout to measure on ``PYTHONPATH``; a sample is taken only when the
main thread lets go of the interpreter, so the peak read is a lower bound of VmHWM's.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import Any


def _rss_kb() -> int:
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * 4


def _frames(ident: int, depth: int = 8) -> list[str]:
    f = sys._current_frames().get(ident)
    out: list[str] = []
    while f is not None and len(out) < depth:
        name = f.f_code.co_filename
        if "mitld_lp" in name:
            out.append(f"{name.split('mitld_lp/')[-1]}:{f.f_lineno} ({f.f_code.co_name})")
        f = f.f_back
    return out


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", help="a model file, or 'sensed'")
    ap.add_argument("--trim-at", default=None, metavar="NAME")
    args = ap.parse_args(argv)
    sys.path[:0] = [str(Path(__file__).resolve().parent)]
    import gc

    import bench_qvbs as bq

    from mitld_lp import startup

    gc.disable()  # the command line's start-up, as bench_qvbs's child runs it
    startup.lean_start()
    if args.model == "sensed":
        import bench_sensed

        model = bench_sensed.case_model(0, False)
    else:
        from mitld_lp import load_model

        model = load_model(args.model, max_states=2_000_000)
    bq.bs.preload()
    gc.enable()
    from mitld_lp import synthesize

    before = _rss_kb()
    best: list[Any] = [0, []]
    done = threading.Event()
    main_id = threading.main_thread().ident

    def sample() -> None:
        while not done.is_set():
            r = _rss_kb()
            if r > best[0]:
                best[:] = [r, _frames(main_id)]
            time.sleep(0.0005)

    trims: list[tuple[int, int]] = []
    if args.trim_at:
        from mitld_lp.util.heap import release_free_memory

        def prof(frame: Any, event: str, arg: Any) -> None:
            if event == "return" and frame.f_code.co_name == args.trim_at:
                a = _rss_kb()
                release_free_memory()
                trims.append((a, _rss_kb()))

        sys.setprofile(prof)
    t = threading.Thread(target=sample, daemon=True)
    t.start()
    r = synthesize(model)
    sys.setprofile(None)
    done.set()
    t.join()
    n = max(r.mdp.n_transitions, 1)
    per = lambda kb: round((kb - before) * 1024 / n, 1)  # noqa: E731
    print(f"peak {per(best[0])} B/t, bracket [{r.lower!r}, {r.upper!r}]")
    for line in best[1]:
        print("   ", line)
    for a, b in trims:
        print(f"{args.trim_at} returns: {per(a)} B/t, after the trim {per(b)}")


if __name__ == "__main__":
    main(sys.argv[1:])
