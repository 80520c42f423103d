"""Shared helpers of the experiment scripts (not a study itself).

Every script: ``main(argv=None)`` with ``--quick`` (a reduced setting, used by the tests)
and ``--out DIR``; it prints the table it reproduces and writes its figures and tables
into ``DIR``.  ``DIR`` defaults to ``experiments/out`` beside the scripts for a full run
and to the scratch folder ``experiments/out/quick`` (not committed) for a quick one, so a
quick run never writes over the committed results.
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

# headless: the scripts only write files.  Set for when a script draws, without
# importing matplotlib here: a benchmark's worker processes import this module, and
# matplotlib's import (~0.4 s CPU) would be counted in the process times it measures.
os.environ["MPLBACKEND"] = "Agg"

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
MODELS = ROOT / "models"
DEFAULT_OUT = HERE / "out"
QUICK_OUT = DEFAULT_OUT / "quick"


def parser(description: str) -> argparse.ArgumentParser:
    """An argument parser with the options every experiment has."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--quick", action="store_true",
                    help="reduced setting (seconds; what the tests run)")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"directory for figures and tables (default {DEFAULT_OUT}, "
                         f"with --quick {QUICK_OUT})")
    return ap


def out_dir(args: argparse.Namespace) -> Path:
    """The output folder of a run (see the module docstring), created if needed."""
    path = args.out if args.out is not None else QUICK_OUT if args.quick else DEFAULT_OUT
    path.mkdir(parents=True, exist_ok=True)
    return path


def model_path(name: str) -> Path:
    """A model file: an existing path as given, else ``models/NAME`` of the repository."""
    p = Path(name)
    return p if p.exists() else MODELS / name


def write_text(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def write_csv(path: Path, header: Sequence[str], rows: Sequence[Sequence[object]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(rows)
    return path


def write_tables(out: Path, stem: str, header: Sequence[str],
                 rows: Sequence[Sequence[object]]) -> None:
    """The results as ``stem.csv`` and ``stem.md`` in ``out``, said on the terminal."""
    write_csv(out / f"{stem}.csv", header, rows)
    write_text(out / f"{stem}.md", markdown_table(header, rows))
    print(f"wrote {out / f'{stem}.csv'}, {out / f'{stem}.md'}")


def text_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A plain fixed-width table (right-aligned columns) for the terminal."""
    cells = [[str(h) for h in header]] + [[str(c) for c in r] for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in cells]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    lines = ["| " + " | ".join(str(h) for h in header) + " |",
             "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def shown(path: Path) -> str:
    """``path`` relative to the working directory when below it (for printing)."""
    try:
        return os.path.relpath(path)
    except ValueError:  # another drive
        return str(path)


def storm_pmax(mdp: Any, goal: Any) -> tuple[float | None, float | None]:
    """Storm's ``Pmax=? [F "accept"]`` at the initial state of ``mdp`` exported as DRN
    with ``goal`` labelled accept, and Storm's seconds (parse and check); ``(None,
    None)`` without stormpy."""
    try:
        import stormpy
    except ImportError:
        return None, None
    from mitld_lp.solvers.export import write_drn

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "m.drn"
        write_drn(mdp, goal, path)
        t0 = time.perf_counter()
        model = stormpy.build_model_from_drn(str(path))
        prop = stormpy.parse_properties('Pmax=? [F "accept"]')[0]
        checked = stormpy.model_checking(model, prop, only_initial_states=True)
        value = float(checked.get_value_vector()[model.initial_states[0]])
        return value, time.perf_counter() - t0
