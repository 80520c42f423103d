"""The own PRISM parser (:mod:`mitld_lp.worlds.prism_own`) against the stormpy route on QVBS.

Every PRISM MDP instance of ``--qvbs`` (each open-parameter setting of each file, at most
``--max-states`` states by QVBS's count; ``--quick``: 20,000) is loaded twice by
``load_prism``: as it loads now (the own parse where it takes the file) and with the own
parse turned off (stormpy parses; the own explorer or Storm's builder builds, as before).
The two worlds are the same when they have the same states in the same order (their
valuations), the same initial state, the same choices with the same names, the same
rows (targets and probabilities, compared exactly) and the same labels.  Printed per
instance: whether the own parse took it (else why not), states, the two loads' CPU
seconds, and same or not.

    python experiments/prism_front_check.py --qvbs /work/shared/qvbs [--quick] \\
        [--only consensus csma] [--max-states 300000] [--out DIR]

``--horizon K`` loads each world for the task ``F[0,K] LABEL`` (the file's first label)
instead: the load the lazy route would take, which the own route takes when the world
is whole within the lazy route's first exploration (``--max-states 4096`` for those).
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's package

from qvbs_door import entries  # noqa: E402

from mitld_lp.worlds import prism  # noqa: E402
from mitld_lp.worlds.table import LateNames  # noqa: E402

_OPEN = re.compile(r"^\s*const\s+(?:int\s+|double\s+|bool\s+)?([A-Za-z_]\w*)\s*;", re.M)


def instances(qvbs: Path, max_states: int, only: list[str]) -> list[tuple[str, Path, dict]]:
    """``(name, file, constants)`` of every PRISM setting within ``max_states``."""
    out = []
    for e in entries(qvbs):
        if e.meta.get("original") != "PRISM" or not e.prism:
            continue
        if only and e.folder.name not in only:
            continue
        path = e.folder / e.prism[0]
        if not path.is_file():
            continue
        open_ = set(_OPEN.findall(path.read_text(encoding="utf-8")))
        fixed = {v["name"]: v["value"] for v in e.entry.get("file-parameter-values", [])}
        for setting in e.entry.get("open-parameter-values", []):
            values = {**fixed, **{v["name"]: v["value"] for v in setting.get("values", [])}}
            states = [s["number"] for s in setting.get("states", []) if "number" in s]
            if not states or states[0] > max_states:
                continue
            given = {k: v for k, v in values.items() if k in open_}
            values_ = "-".join(str(v).lower() for v in given.values())
            name = f"{path.stem}.{values_}" if values_ else path.stem
            if name not in {x[0] for x in out}:
                out.append((name, path, given))
    return out


def names_of(game: Any) -> list[str]:
    t = game._tables  # noqa: SLF001 - the check reads the layout whole
    names = t.action_names
    if isinstance(names, LateNames):
        codes, table = names.names_of(np.arange(t.action_index.size))
        return [table[k] for k in codes.tolist()]
    return [names[k] if k >= 0 else "" for k in t.action_index.tolist()]


def same(a: Any, b: Any) -> str:
    """"" when the two games are the same world (module docstring), else how not."""
    ta, tb = a._tables, b._tables  # noqa: SLF001
    if a.variables != b.variables:
        return f"variables {a.variables} / {b.variables}"
    if len(a.states) != len(b.states):
        return f"states {len(a.states)} / {len(b.states)}"
    va = np.asarray([a.states[i] for i in range(len(a.states))], dtype=object)
    vb = np.asarray([b.states[i] for i in range(len(b.states))], dtype=object)
    if not (va == vb).all():
        return "the states' order or values"
    if a.initial != b.initial:
        return "initial state"
    for name in ("choices", "branches", "targets"):
        if not np.array_equal(getattr(ta, name), getattr(tb, name)):
            return name
    if not np.array_equal(ta.probabilities, tb.probabilities):
        d = np.abs(ta.probabilities - tb.probabilities).max()
        return f"probabilities (largest difference {d:.3g})"
    if a.proposition_names != b.proposition_names:
        return "label names"
    la = [ta.label_sets[k] for k in ta.label_index.tolist()]
    lb = [tb.label_sets[k] for k in tb.label_index.tolist()]
    if la != lb:
        return "labels"
    if names_of(a) != names_of(b):
        return "choice names"
    return ""


def load(path: Path, given: dict, own: bool, task: Any = None) -> tuple[Any, float, str]:
    saved = prism.own_load
    reason: list[str] = []

    class Catch(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            text = record.getMessage()
            if "not the own" in text:
                reason.append(text.split(": ", 2)[-1])

    handler = Catch(logging.DEBUG)
    logger = logging.getLogger("mitld_lp.worlds.prism")
    logger.addHandler(handler)
    logger.setLevel(logging.DEBUG)
    if not own:
        prism.own_load = lambda *a, **k: None
    try:
        t = time.process_time()
        game = prism.load_prism(path, constants=given, task=task)
        return game, time.process_time() - t, "; ".join(reason)
    finally:
        prism.own_load = saved
        logger.removeHandler(handler)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, default=Path("/work/shared/qvbs"))
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", nargs="*", default=[])
    ap.add_argument("--max-states", type=int, default=300_000)
    ap.add_argument("--horizon", type=int, default=None,
                    help="load for the task F[0,K] of the file's first label")
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).resolve().parent / "out" / "quick" / "prism_front")
    args = ap.parse_args(argv)
    limit = 20_000 if args.quick else args.max_states
    rows, different, taken = [], 0, 0
    for name, path, given in instances(args.qvbs, limit, args.only):
        task = None
        if args.horizon is not None:
            from mitld_lp.logic.parser import parse
            from mitld_lp.worlds.prism_parse import parse as parse_prism

            labels = parse_prism(path.read_text(encoding="utf-8")).labels
            if not labels:
                continue
            task = parse(f"F[0,{args.horizon}] {labels[0][0]}")
        try:
            mine, t_own, why = load(path, given, own=True, task=task)
            theirs, t_storm, _ = load(path, given, own=False, task=task)
        except Exception as exc:  # noqa: BLE001 - reported per instance
            rows.append(f"{name}: error {type(exc).__name__}: {exc}")
            different += 1
            continue
        took = not why and "stormpy" not in mine.source and mine.recipe is not None
        verdict = same(mine, theirs)
        different += bool(verdict)
        taken += took and not why
        rows.append(f"{name:45s} {len(mine.states):>9,} states  own parse "
                    f"{'yes' if not why else 'no (' + why + ')'}  load {t_own:.3f}s vs "
                    f"stormpy route {t_storm:.3f}s  {'same' if not verdict else verdict}")
        print(rows[-1], flush=True)
    summary = (f"{len(rows)} instances, {len(rows) - different} the same world, "
               f"{different} different; the own parse took {taken}")
    print(summary)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "prism_front_check.txt").write_text("\n".join(rows + [summary]) + "\n")
    return 1 if different else 0


if __name__ == "__main__":
    raise SystemExit(main())
