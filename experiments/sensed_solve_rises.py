"""Profile: where the sensed solve's resident size rises, call by call, one run.

The sensed case of ``bench_sensed.py`` (issue 45's row, bus 2's camera at 0.5, epsilon
0.01; ``--quick``: its smallest case) is solved by ``synthesize`` ``--solves`` times in
this one process.  During each solve (from the analysis's start to the route's answer)
every call and return of a function of the package reads the process's resident size
(``/proc/self/statm``), so a rise is charged to the call that was running when it was
read.  Per solve:

* the bracket, its CPU seconds (inflated by the profile hook: compare solves with each
  other, not with other benchmarks), the resident size at its start and its peak, both
  in bytes a transition above the size before the first build;
* the innermost calls open at the peak;
* every rise of at least ``--min-rise`` bytes a transition between two reads, with the
  three innermost calls open and the size after it.

The first solve of a process also loads the solvers' kernels; the second shows what a
solve holds without that.  Linux only (``/proc``).

Run: ``python experiments/sensed_solve_rises.py [--quick] [--out DIR] [--solves N]
[--min-rise B]``; writes ``sensed_solve_rises.md`` to the output folder."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any

import _common as C
import bench_sensed as B


class Rises:
    """The resident size read at each call and return of the package's functions."""

    def __init__(self) -> None:
        self.fd = os.open("/proc/self/statm", os.O_RDONLY)
        self.page = os.sysconf("SC_PAGE_SIZE")
        self.events: list[tuple[str, tuple[str, ...], int]] = []
        self.open: list[str] = []

    def rss(self) -> int:
        os.lseek(self.fd, 0, 0)
        return int(os.read(self.fd, 100).split()[1]) * self.page

    def hook(self, frame: Any, event: str, _: Any) -> None:
        if event not in ("call", "return"):
            return
        code = frame.f_code
        if "mitld_lp" not in code.co_filename:
            return
        name = code.co_filename.split("mitld_lp" + os.sep)[-1] + ":" + code.co_name
        if event == "call":
            self.open.append(name)
        self.events.append((event, tuple(self.open[-3:]), self.rss()))
        if event == "return" and self.open:
            self.open.pop()


def solve_once(model: Any, rises: Rises) -> tuple[Any, float, int]:
    """One ``synthesize`` of ``model``, the hook set from the analysis's start to the
    route's answer; the result, the solve's CPU seconds and the size at its start."""
    import mitld_lp.routes.sensed_solve as route
    import mitld_lp.solvers.analysis as analysis
    from mitld_lp import synthesize

    start: dict[str, float] = {}
    analyse, solve = analysis.analyse, route.solve_sensed

    def hooked_analyse(*args: Any, **kwargs: Any) -> Any:
        if not start:
            start["rss"], start["cpu"] = rises.rss(), time.process_time()
            sys.setprofile(rises.hook)
        return analyse(*args, **kwargs)

    def hooked_solve(*args: Any, **kwargs: Any) -> Any:
        try:
            return solve(*args, **kwargs)
        finally:
            sys.setprofile(None)
            start["end"] = time.process_time()

    analysis.analyse, route.solve_sensed = hooked_analyse, hooked_solve
    try:
        result = synthesize(model)
    finally:
        analysis.analyse, route.solve_sensed = analyse, solve
    return result, start["end"] - start["cpu"], int(start["rss"])


def report(k: int, result: Any, cpu: float, start: int, rises: Rises, base: int,
           per: float, min_rise: float) -> list[str]:
    """The lines of one solve's section (module docs)."""
    def bt(size: int) -> str:
        return f"{(size - base) / per:.1f}"

    peak = max(r for _, _, r in rises.events)
    at = next(i for i, (_, _, r) in enumerate(rises.events) if r == peak)
    lines = [f"### solve {k + 1}", "",
             f"bracket [{result.lower!r}, {result.upper!r}], certified {result.certified}; "
             f"solve CPU {cpu:.3f} s (hooked); resident at its start {bt(start)}, "
             f"peak {bt(peak)} B/t (above the size before the first build); "
             f"the calls open at the peak (innermost last): "
             + " > ".join(rises.events[at][1]), "",
             "| rise B/t | after B/t | event | calls open (innermost first) |",
             "|---|---|---|---|"]
    prev = start
    for event, calls, size in rises.events:
        if size - prev >= min_rise * per:
            lines.append(f"| +{(size - prev) / per:.1f} | {bt(size)} | {event} | "
                         + " < ".join(reversed(calls)) + " |")
        prev = size
    return [*lines, ""]


def main(argv: list[str] | None = None) -> int:
    ap = C.parser(__doc__.splitlines()[0])
    ap.add_argument("--solves", type=int, default=2, help="solves in the process (default 2)")
    ap.add_argument("--min-rise", type=float, default=0.3,
                    help="the least rise listed, bytes a transition (default 0.3)")
    args = ap.parse_args(argv)
    if args.solves < 1:
        ap.error(f"--solves: at least 1, got {args.solves}")
    if not Path("/proc/self/statm").exists():
        ap.error("this profile reads /proc/self/statm (Linux only)")
    out = C.out_dir(args)
    case = (B.QUICK if args.quick else B.FULL)[0]
    model = B.case_model(0, args.quick)
    rises = Rises()
    base = rises.rss()
    lines = [f"## The sensed solve's resident rises: {B.name_of(case)}", ""]
    for k in range(args.solves):
        rises.events.clear()
        result, cpu, start = solve_once(model, rises)
        if not rises.events:
            raise SystemExit(f"{B.name_of(case)}: the solve read no size (was it solved on "
                             "the sensed route?)")
        per = float(result.mdp.n_transitions)
        if k == 0:
            lines.append(f"{result.mdp.n_states:,} states, {int(per):,} transitions.")
            lines.append("")
        lines += report(k, result, cpu, start, rises, base, per, args.min_rise)
        del result
    text = "\n".join(lines)
    print(text)
    print("written:", C.shown(C.write_text(out / "sensed_solve_rises.md", text)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
