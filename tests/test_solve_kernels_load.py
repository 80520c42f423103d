"""experiments/numba_load.py: numba's load part by part, in fresh processes, whole and
narrow (:mod:`mitld_lp.util.numba_narrow`), with the block kernel's bracket beside
(the two-state block x = 1/4 + x/2: exactly 1/2)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("numba")
ROOT = Path(__file__).resolve().parent.parent


def test_numba_load_prints_every_part_and_the_kernels_bracket() -> None:
    path = os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])
    done = subprocess.run([sys.executable, str(ROOT / "experiments" / "numba_load.py"),
                           "--rounds", "1"], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": path}, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    low, high = map(float, re.search(r"\[([0-9.]+), ([0-9.]+)\]", done.stdout).groups())
    assert low <= 0.5 <= high and high - low < 1e-9
    assert "every load" in done.stdout  # the loads' brackets are the same bits
    for part in ("import numba", "typing registries", "numba's runtime (NRT)",
                 "target registries (rest)", "numba.np.arrayobj (envs)",
                 "graph kernel, first call", "block kernel, first call",
                 "a level kernel, first call", "total"):
        # per load: median s, least s, resident MB the part adds
        # whole, narrow and the loader's rounds (without numba): three triples
        cells = re.search(rf"^{re.escape(part)}" + r"\s+([0-9.]+)\s+([0-9.]+)\s+(-?[0-9.]+)" * 3
                          + "$", done.stdout, re.MULTILINE)
        assert cells is not None, part
        figures = list(map(float, cells.groups()))
        for median, least in zip(figures[0::3], figures[1::3], strict=True):
            assert least <= median
