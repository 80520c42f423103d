"""Count what a design that skips the per-level walk could save on the QVBS deadline
products: their levels, how many have a state with several choices, the runs of
consecutive single-choice levels, and the *choice depth* (the longest chain of states
with several choices, single-choice states counted as 0): the levels left to walk if
every single-choice state were eliminated.

Each instance is posed as ``bench_qvbs.py`` poses it and solved once; the counts are
read from the LP stage's single levels (:class:`~mitld_lp.solvers.topological.
SingleLevels`), over the quotient the solve works on.

::

    python experiments/deadline_levels.py --qvbs qcomp/benchmarks --out experiments/results

Written: ``deadline_levels.md``.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import _common  # noqa: E402
import profile_solve as ps  # noqa: E402  (the same instances, posed the same way)

INSTANCES = ("zeroconf_dl.1000-1-false-30.deadline_max", "firewire_dl.3-600.deadline",
             "wlan_dl.0-80.deadline", "firewire_dl.36-400.deadline")
COLUMNS = ("instance", "value", "quotient_states", "single_states", "choice_states",
           "choices", "levels", "levels_with_choices", "single_choice_levels",
           "single_choice_runs", "longest_run_levels", "states_a_level", "choice_depth")


def counts(q: Any, sl: Any) -> dict[str, int | float]:
    """The counts of one quotient ``q`` and its single levels ``sl``."""
    import numpy as np

    from mitld_lp.solvers.rows import gather_ranges

    b = q.order
    per_state = np.diff(sl.state_choice)
    several = per_state > 1
    level = np.repeat(np.arange(b.n_levels), np.diff(sl.level_state))
    has_choice = np.zeros(b.n_levels, dtype=bool)
    has_choice[level[several]] = True
    has_single = np.zeros(b.n_levels, dtype=bool)
    has_single[level] = True
    single_choice = has_single & ~has_choice
    edges = np.diff(np.concatenate([[0], single_choice.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    # the choice depth, level by level upward: a state's deepest successor, plus one if
    # it has several choices (the walk the design would keep)
    depth = np.zeros(q.n_states, dtype=np.int64)
    mark = np.zeros(q.n_states, dtype=np.int64)
    mark[sl.states[several]] = 1
    m = q.matrix
    for k in range(b.n_levels):
        states = sl.states[sl.level_state[k]:sl.level_state[k + 1]]
        if not states.size:
            continue
        lo, hi = q.row_groups[states], q.row_groups[states + 1]
        choices = gather_ranges(lo, hi)
        owner = np.repeat(np.arange(states.size), hi - lo)
        entries = gather_ranges(m.indptr[choices], m.indptr[choices + 1])
        whose = np.repeat(owner, np.diff(m.indptr)[choices])
        cols = m.indices[entries]
        inside = cols < q.n_states
        deepest = np.zeros(states.size, dtype=np.int64)
        np.maximum.at(deepest, whose[inside], depth[cols[inside]])
        depth[states] = deepest + mark[states]
    return dict(quotient_states=q.n_states, single_states=int(sl.states.size),
                choice_states=int(several.sum()), choices=int(per_state.sum()),
                levels=b.n_levels, levels_with_choices=int(has_choice.sum()),
                single_choice_levels=int(single_choice.sum()),
                single_choice_runs=int(starts.size),
                longest_run_levels=int((stops - starts).max()) if starts.size else 0,
                states_a_level=round(sl.states.size / max(int(has_single.sum()), 1), 1),
                choice_depth=int(depth.max()))


def main(argv: list[str] | None = None) -> int:
    ap = _common.parser(__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True,
                    help="a checkout's benchmarks/ folder of ahartmanns/qcomp")
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    args = ap.parse_args(argv)
    from mitld_lp import load_model, synthesize
    from mitld_lp.solvers import topological

    seen: list[dict[str, Any]] = []
    build = topological.SingleLevels.__init__

    def kept(self: Any, q: Any, b: Any, skip: Any = None, **kw: Any) -> None:
        build(self, q, b, skip, **kw)
        seen.append(counts(q, self))

    topological.SingleLevels.__init__ = kept  # type: ignore[method-assign]
    rows = []
    with tempfile.TemporaryDirectory(prefix="deadline_levels_") as tmp:
        for inst, job in ps.chosen_jobs(args.qvbs, False, set(args.only or INSTANCES),
                                        Path(tmp)):
            seen.clear()
            r = synthesize(load_model(job["model"], max_states=job["max_states"]))
            c = seen[-1]  # the LP stage's single levels
            rows.append([inst.name, f"{r.lower:.6g}", *(c[k] for k in COLUMNS[2:])])
            print(_common.text_table(COLUMNS, rows[-1:]), flush=True)
    text = ("## The deadline products' levels and choices\n\n"
            + _common.markdown_table(COLUMNS, rows)
            + "\n\n`choice_depth`: the longest chain of states with several choices (the "
              "levels left if every single-choice state were eliminated); "
              "`single_choice_runs`: runs of consecutive levels whose states all have one "
              "choice; `states_a_level`: single states over levels that have some.\n")
    _common.write_text(_common.out_dir(args) / "deadline_levels.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
