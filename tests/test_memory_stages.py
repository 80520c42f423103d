"""``experiments/memory_stages.py`` (``bench_qvbs.py --memory``) on a bundled case: the
stages it wraps run inside the synthesis and are put back after it, the outer peak is
the highest of any stage's, and what the product stage keeps, traced, holds at least
the product's own arrays (their sizes read from the result, not from the tracker)."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

from mitld_lp import load_model, synthesize

ROOT = Path(__file__).resolve().parents[1]


def _memory_stages():
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        return importlib.import_module("memory_stages")
    finally:
        sys.path.remove(str(ROOT / "experiments"))


def _writable_clear_refs() -> bool:
    try:
        _memory_stages()._reset_hwm()  # the script's own reset, which the stages use
    except OSError:
        return False
    return True


pytestmark = pytest.mark.skipif(not _writable_clear_refs(),
                                reason="needs Linux's /proc/self/clear_refs")


def test_stages_tracked_inside_the_synthesis_and_put_back() -> None:
    ms = _memory_stages()
    model = load_model(ROOT / "models" / "corridor.toml")
    originals = {(m, a): getattr(importlib.import_module(m), a) for m, a, _ in ms.STAGES}
    result, breakdown = ms.Tracker(traced=True).run(lambda: synthesize(model),
                                                    lambda r: r.mdp.n_transitions)
    for (module, attr), fn in originals.items():  # nothing left wrapped
        assert getattr(importlib.import_module(module), attr) is fn
    stages = breakdown["stages"]
    # the plain route's stages, each once (one analysis for both truncation models)
    for name in ("product", "acceptance", "analysis", "iteration", "certificate"):
        assert stages[name]["calls"] >= 1, name
    assert stages["product"]["calls"] == stages["analysis"]["calls"] == 1
    outer = stages[ms.OUTER]
    for name, row in stages.items():
        assert row["peak"] <= outer["peak"], name
        assert row["traced_peak"] <= outer["traced_peak"], name
        assert row["traced_kept"] <= row["traced_peak"] + 0.1, name
    mdp = result.mdp
    held = sum(np.asarray(a).nbytes for a in (
        mdp.matrix.data, mdp.matrix.indices, mdp.matrix.indptr, mdp.row_groups,
        mdp.choice_actions, mdp.target, mdp.sink, mdp.truncated)) / mdp.n_transitions
    assert stages["product"]["traced_kept"] >= held - 0.1
    assert result.certified
