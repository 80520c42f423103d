"""Where ``synthesize`` peaks in memory, stage by stage (``bench_qvbs.py --memory``).

Each stage function of the plain route (the product, the acceptance target, the graph
analysis, the interval iteration, the LP, the certificate) is wrapped in place where its
caller looks it up at call time, and at every entry and exit of one the tracker reads

* the resident peak since the last boundary (Linux's ``VmHWM``, reset after each read
  by writing ``5`` to ``/proc/self/clear_refs``) and the resident size now, and
* with ``tracemalloc`` on, Python's traced peak since the last boundary
  (``tracemalloc.reset_peak``) and the traced size now (numpy's arrays are traced).

The peak between two boundaries is credited to every stage open then (the outer
``synthesize`` too), so a stage's peak is the highest point reached while it ran; what a
stage keeps is the size at its exit.  Every figure is in bytes above the size just
before ``synthesize``, per product transition.  ``top``: the allocation sites in the
package holding the most traced bytes at the exit of the stage with the highest traced
peak (one snapshot, taken after that stage's figures are read; the peaks are reset
after it, so that it counts in no stage).  ``top_where``: where the synthesis stood when
the traced size was highest (a thread reads it every 5 ms and, at each new high, the
synthesis's innermost frames in the package; no snapshot, nothing allocated).

``at_peak`` (``--at-peak`` when run as a script): a trace function also takes a snapshot
at a call or return of a function of the package when the traced size has passed its
last snapshot's by 5% (from 8 MB above the start; at a return the function's arrays are
still alive), so ``peak_top`` names the allocation sites alive at the highest traced point
itself, not at a stage's exit (numpy's arrays are freed between the two).  The
snapshots' own objects are traced too: in that mode the traced peaks read a little
high, and the run is slower (zeroconf_dl 1000-1-30: 37 s; zeroconf 1000-4, numba loaded
and many traced objects to snapshot, did not finish in 15 minutes); take the stage figures
from a run without it.

Run as a script, it tracks one synthesis in this process (no Storm, no bench): a model
file (a QVBS instance's, as ``bench_qvbs.py`` writes them), a ``bench_sweeps``
instance or a ``bench_sensed`` case (the sensed route: its build is the ``product``
row's, its stages those of the plain route's solve it runs)::

    python experiments/memory_stages.py --model zeroconf.toml --at-peak
    python experiments/memory_stages.py --sweeps bus_scaled_n64_d3 --resident
    python experiments/memory_stages.py --sensed 0  # bench_sensed's case 0 (sensed route)

``numba``: numba is imported only for a large product, inside ``synthesize``, and its
import alone is ~50 MB resident, whatever the product's size.  Where the synthesis
loaded it, that floor (:func:`numba_floor`: the resident growth of ``import numba`` in
a fresh interpreter that has numpy and scipy already, ``numba_mb``) is reported beside
the peak, with the synthesis's peak without it (``without_numba`` in its row): the part
that grows with the product.
"""

from __future__ import annotations

import importlib
import os
import sys
import threading
import tracemalloc
from collections.abc import Callable
from typing import Any

STAGES = (  # (module, attribute, stage name): looked up at call time by their callers
    ("mitld_lp.routes.stages", "product", "product"),
    ("mitld_lp.routes.acceptance", "acceptance", "acceptance"),
    ("mitld_lp.solvers.analysis", "analyse", "analysis"),
    ("mitld_lp.solvers.iteration", "interval_iterations", "iteration"),
    ("mitld_lp.solvers.lp", "solve_lp", "lp"),
    ("mitld_lp.solvers.certify", "certify", "certificate"),
)
#: the sensed route's build, the ``product`` row of a ``--sensed`` case
SENSED_BUILD = ("mitld_lp.sensing.belief", "belief_product", "product")
OUTER = "synthesize"


def _sites(snap: tracemalloc.Snapshot, n: int = 10) -> list[tuple[str, int]]:
    """The ``n`` places in the package holding the most traced bytes: each allocation
    credited to its innermost frame in ``mitld_lp`` (numpy's and scipy's own lines
    name no stage), as ``path:line`` from the package's folder."""
    held: dict[str, int] = {}
    for stat in snap.statistics("traceback"):
        where = "elsewhere"
        for frame in reversed(stat.traceback):  # innermost last
            at = frame.filename.replace(os.sep, "/").rfind("/mitld_lp/")
            if at >= 0:
                where = f"{frame.filename[at + 1:]}:{frame.lineno}"
                break
        held[where] = held.get(where, 0) + stat.size
    return sorted(held.items(), key=lambda kv: -kv[1])[:n]


def _innermost(frame: Any, n: int = 3) -> str:
    """The ``n`` innermost frames of the package from ``frame`` outward, as
    ``path:line (function)`` joined by `` <- `` (no frame is kept: a frame held would
    keep its arrays alive)."""
    where = []
    while frame is not None and len(where) < n:
        name = frame.f_code.co_filename.replace(os.sep, "/")
        if "/mitld_lp/" in name:
            where.append(f"{name[name.rfind('/mitld_lp/') + 1:]}:{frame.f_lineno}"
                         f" ({frame.f_code.co_name})")
        frame = frame.f_back
    return " <- ".join(where)


def _rss() -> int:
    with open("/proc/self/statm", encoding="ascii") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _hwm() -> int:
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise OSError("no VmHWM in /proc/self/status")


def _reset_hwm() -> None:
    with open("/proc/self/clear_refs", "w", encoding="ascii") as f:
        f.write("5")


def numba_floor() -> int:
    """Bytes resident that ``import numba`` adds to an interpreter that has numpy and
    scipy's sparse module already (measured in a child of its own, so that nothing of
    this process counts): the floor a synthesis that loads numba pays at any size."""
    import subprocess

    code = ("import os, numpy, scipy.sparse\n"
            "def rss():\n"
            "    with open('/proc/self/statm') as f:\n"
            "        return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE')\n"
            "a = rss()\nimport numba\nprint(rss() - a)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    return int(out.stdout.strip())


class Tracker:
    """The stages' peaks and kept sizes (module docs); ``traced``: tracemalloc too."""

    def __init__(self, traced: bool, at_peak: bool = False,
                 stages: tuple[tuple[str, str, str], ...] = STAGES) -> None:
        self.stages = stages
        self.traced = traced
        self.at_peak = traced and at_peak
        self.peak_top: list[tuple[str, int]] = []
        self.peak_top_at = 0  # the traced size when peak_top was taken
        self.peak_top_where = ""
        self._snap_level = 0
        self.open: list[str] = []
        self.peak: dict[str, int] = {}  # resident
        self.tpeak: dict[str, int] = {}  # traced
        self.kept: dict[str, int] = {}
        self.tkept: dict[str, int] = {}
        self.calls: dict[str, int] = {}
        self.top: list[tuple[str, int]] = []
        self.top_exit = ""
        self._best_traced = -1
        self.top_stage = ""
        self.top_where = ""
        self._level = 0
        self._done = threading.Event()

    def _sample(self, main: int) -> None:
        """The sampling thread (module docs); ``main``: the synthesis's thread id."""
        while not self._done.wait(0.005):
            now = tracemalloc.get_traced_memory()[0]
            if now <= self._level:
                continue
            self._level = now
            self.top_where = _innermost(sys._current_frames().get(main))
            self.top_stage = self.open[-1] if self.open else ""

    def _trace(self, frame: Any, event: str, arg: Any) -> Any:
        """``at_peak``'s trace function (``sys.settrace``: Python calls only, no C call
        reaches it): a function of the package is watched at its call and its return
        (its lines are not traced), any other is not traced at all."""
        if "/mitld_lp/" not in frame.f_code.co_filename:
            return None
        frame.f_trace_lines = False
        self._watch(frame, event)
        return self._returns

    def _returns(self, frame: Any, event: str, arg: Any) -> Any:
        if event == "return":
            self._watch(frame, event)
        return self._returns

    def _watch(self, frame: Any, event: str) -> None:
        """At a call or return of a function of the package (its locals still alive at
        its return), a snapshot when the traced size has grown 5% past the last one's
        (module docs)."""
        now = tracemalloc.get_traced_memory()[0]
        if now <= self._snap_level:
            return
        where = _innermost(frame)
        self.peak_top = _sites(tracemalloc.take_snapshot(), 14)
        self.peak_top_at = now
        stage = self.open[-1] if self.open else ""
        self.peak_top_where = f"{stage}, {event}: {where}"
        self._snap_level = int(now * 1.05)

    def _boundary(self) -> None:
        hwm = _hwm()
        _reset_hwm()
        t = tracemalloc.get_traced_memory()[1] if self.traced else 0
        if self.traced:
            tracemalloc.reset_peak()
        for name in self.open:
            self.peak[name] = max(self.peak.get(name, 0), hwm)
            self.tpeak[name] = max(self.tpeak.get(name, 0), t)

    def enter(self, name: str) -> None:
        self._boundary()
        self.open.append(name)
        self.calls[name] = self.calls.get(name, 0) + 1

    def exit(self, name: str) -> None:
        self._boundary()
        self.open.remove(name)
        self.kept[name] = _rss()
        if self.traced:
            self.tkept[name] = tracemalloc.get_traced_memory()[0]
            if name != OUTER and self.tpeak.get(name, 0) > self._best_traced:
                self._best_traced = self.tpeak[name]
                self.top_exit = name
                self.top = _sites(tracemalloc.take_snapshot())
                tracemalloc.reset_peak()  # the snapshot counts in no stage
                _reset_hwm()

    def wrap(self, fn: Callable[..., Any], name: str) -> Callable[..., Any]:
        def tracked(*args: Any, **kwargs: Any) -> Any:
            self.enter(name)
            try:
                return fn(*args, **kwargs)
            finally:
                self.exit(name)

        tracked.__wrapped__ = fn  # type: ignore[attr-defined]
        return tracked

    def install(self) -> list[tuple[Any, str, Any]]:
        """The stages wrapped in place; the originals, to put back."""
        saved = []
        for module, attr, name in self.stages:
            try:
                mod = importlib.import_module(module)
            except ImportError:  # an older checkout (--compare) without the module
                continue
            if hasattr(mod, attr):
                saved.append((mod, attr, getattr(mod, attr)))
                setattr(mod, attr, self.wrap(getattr(mod, attr), name))
        return saved

    def run(self, call: Callable[[], Any], transitions_of: Callable[[Any], int],
            ) -> tuple[Any, dict[str, Any]]:
        """``call()`` (the synthesis) tracked; its result and the breakdown: per stage,
        the resident and traced peaks and what it keeps, in bytes above the start per
        transition (``transitions_of(result)``)."""
        saved = self.install()
        had_numba = "numba" in sys.modules
        sampler = None
        if self.traced:
            tracemalloc.start(16)
            sampler = threading.Thread(target=self._sample, args=(threading.get_ident(),),
                                       daemon=True)
        _reset_hwm()
        base, tbase = _rss(), (tracemalloc.get_traced_memory()[0] if self.traced else 0)
        self._level = tbase
        self._snap_level = tbase + (8 << 20)
        if sampler is not None:
            sampler.start()
        self.enter(OUTER)
        if self.at_peak:
            sys.settrace(self._trace)
        try:
            out = call()
        finally:
            sys.settrace(None)
            self.exit(OUTER)
            self._done.set()
            if sampler is not None:
                sampler.join()
            if self.traced:
                tracemalloc.stop()
            for mod, attr, fn in saved:  # the stages as they were
                setattr(mod, attr, fn)
        n = max(transitions_of(out), 1)
        names = [OUTER] + list(dict.fromkeys(s for _, _, s in self.stages if s in self.calls))

        def per(x: int, b: int) -> float:
            return round(max(x - b, 0) / n, 1)

        rows = {s: dict(calls=self.calls[s], peak=per(self.peak[s], base),
                        kept=per(self.kept[s], base),
                        **(dict(traced_peak=per(self.tpeak[s], tbase),
                                traced_kept=per(self.tkept[s], tbase)) if self.traced
                           else {})) for s in names}
        loaded = not had_numba and "numba" in sys.modules  # by the synthesis
        floor = numba_floor() if loaded else 0
        rows[OUTER]["without_numba"] = per(self.peak[OUTER] - floor, base)
        return out, dict(stages=rows, base_mb=round(base / 2**20, 1),
                         numba_mb=round(floor / 2**20, 1), transitions=n,
                         top_exit=self.top_exit, top_stage=self.top_stage,
                         top_where=self.top_where, top_traced=per(self._level, tbase),
                         top=[(w, round(b / n, 1)) for w, b in self.top],
                         peak_top=[(w, round(b / n, 1)) for w, b in self.peak_top],
                         peak_top_at=per(self.peak_top_at, tbase),
                         peak_top_where=self.peak_top_where)


def text(name: str, breakdown: dict[str, Any]) -> str:
    """The breakdown of one instance as a markdown table and the top allocation sites."""
    rows = breakdown["stages"]
    cols = ["stage", "calls", "peak", "kept", "traced_peak", "traced_kept"]
    out = [f"### {name} (bytes per transition above the {breakdown['base_mb']} MB before "
           "`synthesize`)\n", "| " + " | ".join(cols) + " |",
           "|" + "---|" * len(cols)]
    for stage, r in rows.items():
        out.append("| " + " | ".join(str(r.get(c, "")) if c != "stage" else stage
                                     for c in cols) + " |")
    if "numba_mb" in breakdown:
        mb, outer = breakdown["numba_mb"], rows[OUTER]
        out.append(f"\nnumba not loaded in `{OUTER}`." if not mb else
                   f"\nnumba loaded by `{OUTER}`: its import alone {mb} MB resident (in a "
                   f"fresh interpreter), {round(mb * 2**20 / breakdown['transitions'], 1)} "
                   f"bytes a transition; the peak without that floor "
                   f"{outer['without_numba']} bytes a transition, {outer['peak']} with it.")
    if breakdown["top_where"]:
        out.append(f"\nThe traced size was highest ({breakdown['top_traced']} bytes a "
                   f"transition) in `{breakdown['top_stage']}`, at "
                   f"`{breakdown['top_where']}`.")
    if breakdown["top"]:
        out.append(f"\nAt the exit of `{breakdown['top_exit']}` (the stage with the "
                   "highest traced peak), the largest allocation sites in the package "
                   "(each allocation at its innermost frame in it), bytes per transition:\n")
        out += [f"- `{w}`: {b}" for w, b in breakdown["top"]]
    if breakdown.get("peak_top"):
        out.append(f"\nAlive at the last snapshot near the traced peak "
                   f"({breakdown['peak_top_at']} bytes a transition, in "
                   f"`{breakdown['peak_top_where']}`), bytes per transition:\n")
        out += [f"- `{w}`: {b}" for w, b in breakdown["peak_top"]]
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """One synthesis tracked in this process (module docs); prints its table."""
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--model", help="a model file (e.g. one bench_qvbs.py writes)")
    what.add_argument("--sweeps", help="a bench_sweeps instance, e.g. bus_scaled_n64_d3")
    what.add_argument("--sensed", type=int, metavar="INDEX",
                      help="bench_sensed's case INDEX (0: the issue's 1.08e6 transitions)")
    ap.add_argument("--max-states", type=int, default=2_000_000)
    ap.add_argument("--resident", action="store_true",
                    help="resident sizes only (no tracemalloc: its own cost out)")
    ap.add_argument("--at-peak", action="store_true",
                    help="also the allocation sites alive near the traced peak")
    args = ap.parse_args(argv)
    here = os.path.dirname(os.path.abspath(__file__))
    if here not in sys.path:
        sys.path.insert(0, here)
    import bench_sweeps

    from mitld_lp import load_model, synthesize

    if args.model:
        name, model = args.model, load_model(args.model, max_states=args.max_states)
    elif args.sensed is not None:
        import bench_sensed

        case = bench_sensed.FULL[args.sensed]
        name, model = bench_sensed.name_of(case), bench_sensed.case_model(args.sensed, False)
    else:
        import bench_scaling

        family, n, d = args.sweeps.rsplit("_", 2)
        inst = bench_scaling.Instance(family, int(n[1:]), int(d[1:]))
        name, model = inst.name, bench_sweeps._model(inst)
    bench_sweeps.preload()  # the solver modules, as both benches load them before
    stages = (SENSED_BUILD, *STAGES) if args.sensed is not None else STAGES
    result, breakdown = Tracker(traced=not args.resident, at_peak=args.at_peak,
                                stages=stages).run(
        lambda: synthesize(model), lambda r: r.mdp.n_transitions)
    print(text(name, breakdown))
    print(f"answer: [{result.lower!r}, {result.upper!r}], certified={result.certified}")
    return breakdown


if __name__ == "__main__":
    main()
