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
before ``synthesize``, per product transition.  ``top`` lists the allocation sites that
held the most traced memory at the traced peak's stage exit (a snapshot taken at the
exit of the stage with the highest traced peak, so at most one snapshot a run).
"""

from __future__ import annotations

import importlib
import os
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


class Tracker:
    """The stages' peaks and kept sizes (module docs); ``traced``: tracemalloc too."""

    def __init__(self, traced: bool) -> None:
        self.traced = traced
        self.open: list[str] = []
        self.peak: dict[str, int] = {}  # resident
        self.tpeak: dict[str, int] = {}  # traced
        self.kept: dict[str, int] = {}
        self.tkept: dict[str, int] = {}
        self.calls: dict[str, int] = {}
        self.top: list[tuple[str, int]] = []
        self.top_stage = ""
        self._best_traced = -1

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
                self.top_stage = name
                self.top = _sites(tracemalloc.take_snapshot())

    def wrap(self, fn: Callable[..., Any], name: str) -> Callable[..., Any]:
        def tracked(*args: Any, **kwargs: Any) -> Any:
            self.enter(name)
            try:
                return fn(*args, **kwargs)
            finally:
                self.exit(name)

        tracked.__wrapped__ = fn  # type: ignore[attr-defined]
        return tracked

    def install(self) -> None:
        for module, attr, name in STAGES:
            try:
                mod = importlib.import_module(module)
            except ImportError:  # an older checkout (--compare) without the module
                continue
            if hasattr(mod, attr):
                setattr(mod, attr, self.wrap(getattr(mod, attr), name))

    def run(self, call: Callable[[], Any], transitions_of: Callable[[Any], int],
            ) -> tuple[Any, dict[str, Any]]:
        """``call()`` (the synthesis) tracked; its result and the breakdown: per stage,
        the resident and traced peaks and what it keeps, in bytes above the start per
        transition (``transitions_of(result)``)."""
        self.install()
        if self.traced:
            tracemalloc.start(16)
        _reset_hwm()
        base, tbase = _rss(), (tracemalloc.get_traced_memory()[0] if self.traced else 0)
        self.enter(OUTER)
        try:
            out = call()
        finally:
            self.exit(OUTER)
            if self.traced:
                tracemalloc.stop()
        n = max(transitions_of(out), 1)
        names = [OUTER] + [s for _, _, s in STAGES if s in self.calls]

        def per(x: int, b: int) -> float:
            return round(max(x - b, 0) / n, 1)

        rows = {s: dict(calls=self.calls[s], peak=per(self.peak[s], base),
                        kept=per(self.kept[s], base),
                        **(dict(traced_peak=per(self.tpeak[s], tbase),
                                traced_kept=per(self.tkept[s], tbase)) if self.traced
                           else {})) for s in names}
        return out, dict(stages=rows, base_mb=round(base / 2**20, 1),
                         top_stage=self.top_stage,
                         top=[(w, round(b / n, 1)) for w, b in self.top])


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
    if breakdown["top"]:
        out.append(f"\nAt the exit of `{breakdown['top_stage']}` (the highest traced "
                   "peak), the largest traced allocation sites, bytes per transition:\n")
        out += [f"- `{w}`: {b}" for w, b in breakdown["top"]]
    return "\n".join(out) + "\n"
