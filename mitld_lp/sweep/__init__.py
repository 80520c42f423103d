"""Sweeps: one model file solved at many points of its parameters.

    sweep file --load_sweep--> points --engine--> rows --> results file (CSV / Parquet)

A sweep file (:mod:`mitld_lp.sweep.spec`) names a base model file and the key paths to
vary; each point is the base model with those values, solved by ``synthesize``
(:mod:`mitld_lp.sweep.rows`), in this process, a process pool or on a Dask cluster
(:mod:`mitld_lp.sweep.engines`).  Each point gives one row of the results file
(:mod:`mitld_lp.sweep.results`) as soon as it finishes, so that a sweep stopped half
way and run again computes only the points missing from the file (points are matched
by their parameter values).  A point that fails is a row with its status and error,
never the end of the sweep.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from mitld_lp.sweep.results import Results, point_key
from mitld_lp.sweep.rows import RESULT_COLUMNS, TIME_COLUMNS, PointTask, Settings
from mitld_lp.sweep.spec import Sweep, SweepError, load_sweep
from mitld_lp.util.progress import bar as progress_bar

__all__ = ["sweep", "run_sweep", "SweepRun", "Sweep", "SweepError", "Settings", "load_sweep",
           "TIME_COLUMNS"]


@dataclass(frozen=True, slots=True)
class SweepRun:
    """What :func:`run_sweep` returns.

    Attributes:
        sweep: the sweep.
        columns: the columns of a row (meta, parameters, results).
        rows: one record per point of the sweep, in the sweep's order (a point's
            record read from the results file when it was already there).
        computed: how many points were solved by this run.
        reused: how many were already in the results file.
        path: the results file, or ``None``.
    """

    sweep: Sweep
    columns: tuple[str, ...]
    rows: tuple[dict[str, Any], ...]
    computed: int
    reused: int
    path: Path | None

    @property
    def failed(self) -> tuple[dict[str, Any], ...]:
        """The rows without a certified answer."""
        return tuple(r for r in self.rows if not r["certified"])


_FAILED = frozenset({"model_error", "budget", "error", "lost"})


def run_sweep(
    spec: Sweep | str | os.PathLike[str],
    results: str | os.PathLike[str] | None = None,
    *,
    workers: int = 1,
    dask: str | None = None,
    retries: int = 2,
    force: bool = False,
    retry_failed: bool = False,
    progress: bool | None = False,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> SweepRun:
    """Solve every point of a sweep that ``results`` does not hold yet.

    ``spec``: a sweep file or a loaded :class:`Sweep`.  ``results``: the ``.csv`` or
    ``.parquet`` file the rows go to (``None``: none, every point is solved); a file of
    another sweep is refused unless ``force``, which starts it anew.  ``workers``: the
    number of local processes (1: in this process); ``dask``: the address of a Dask
    scheduler (``tcp://host:8786``) instead; ``retries``: how often Dask runs a failed
    task again.  ``retry_failed``: also solve again the points whose row has a failure
    status (``model_error``, ``budget``, ``error``, ``lost``).  ``progress``: a bar over
    the points (:func:`mitld_lp.util.progress.bar`: ``None`` on a terminal only).
    ``on_row(row)`` is called after each new row is recorded.
    Raises :class:`SweepError` for a bad sweep or results file (before any point)."""
    sw = spec if isinstance(spec, Sweep) else load_sweep(spec)
    if workers < 1:
        raise SweepError(f"workers: must be at least 1, got {workers}")
    if retries < 0:
        raise SweepError(f"retries: must be at least 0, got {retries}")
    if dask is not None and workers != 1:
        raise SweepError("give either workers or a Dask address, not both")
    from mitld_lp.sweep import engines

    # the scheduler answers before the results file is touched: a refused address
    # leaves no file behind (nor a header alone)
    client = None if dask is None else engines.connect(dask)
    try:
        return _run(sw, results, client, workers=workers, retries=retries, force=force,
                    retry_failed=retry_failed, progress=progress, on_row=on_row)
    finally:
        if client is not None:
            client.close()


def _run(sw: Sweep, results: str | os.PathLike[str] | None, client: Any, *, workers: int,
         retries: int, force: bool, retry_failed: bool, progress: bool,
         on_row: Callable[[dict[str, Any]], None] | None) -> SweepRun:
    """:func:`run_sweep` once its arguments are checked (``client``: a Dask client, or
    None for local processes)."""
    from mitld_lp.sweep import engines

    store = None if results is None else Results(results, sw.name, sw.sweep_id, sw.columns,
                                                 force=force)
    keys = [point_key(p) for p in sw.points]
    done: dict[str, dict[str, Any]] = {}
    if store is not None:
        kept = []
        for row in store.rows:
            if retry_failed and row["status"] in _FAILED:
                continue
            kept.append(row)
            done[point_key(row[c] for c in sw.columns)] = row
        if len(kept) != len(store.rows):
            store.rewrite(kept)
    todo_keys = set(keys) - set(done)
    source = os.fspath(sw.model_path)
    tasks, queued = [], set()
    quiet = replace(sw.settings, progress=False)  # one bar, the sweep's: none per point
    for i, (point, key) in enumerate(zip(sw.points, keys, strict=True)):
        if key in todo_keys and key not in queued:  # a point listed twice is solved once
            queued.add(key)
            tasks.append(PointTask(i, sw.model_text(point), source, quiet))
    reused = sum(1 for k in set(keys) if k in done)
    if client is not None:
        finished = engines.dask_cluster(tasks, client, retries)
    elif workers > 1 and len(tasks) > 1:
        finished = engines.process_pool(tasks, workers)
    else:
        finished = engines.serial(tasks)
    bar = progress_bar(progress, total=len(tasks), desc=sw.name, unit="point",
                       leave=False)
    computed = 0
    try:
        for task, result in finished:
            point = sw.points[task.index]
            row = {"sweep": sw.name, "sweep_id": sw.sweep_id,
                   **dict(zip(sw.columns, point, strict=True)), **result}
            if store is not None:
                store.add(row)
            done[keys[task.index]] = row
            computed += 1
            bar.update(1)
            if on_row is not None:
                on_row(row)
    finally:
        finished.close()  # the engine's own ending (pending tasks cancelled) comes first
        bar.close()
        if store is not None:
            store.close()
    columns = ("sweep", "sweep_id", *sw.columns, *RESULT_COLUMNS)
    rows = tuple(done[k] for k in dict.fromkeys(keys))
    return SweepRun(sw, columns, rows, computed, reused, None if store is None else store.path)


def sweep(
    spec: Sweep | str | os.PathLike[str],
    results: str | os.PathLike[str] | None = None,
    **options: Any,
) -> Any:
    """:func:`run_sweep` (same arguments), its rows as a pandas ``DataFrame`` when pandas
    is installed, else as a list of dicts; one row per point, in the sweep's order."""
    run = run_sweep(spec, results, **options)
    records = [dict(r) for r in run.rows]
    try:
        import pandas as pd
    except ImportError:
        return records
    return pd.DataFrame.from_records(records, columns=list(run.columns))
