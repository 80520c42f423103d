"""The bus case with a camera that misses bus 1, bus 2's law known only within a band
and a puddle to avoid always, solved, exported as a chain and re-checked by Storm.

``models/bus_puddle.toml`` (``G !puddle`` and a bus to catch) with
``[sensors] b1 = { detect = d }`` and bus 2's geometric law widened to a band: the
``sensed`` route's answer with a band (the sensed optimum at a law of the band, its
worst case over the band on its controlled chain: ``lower``; the least of the sound
upper bounds: ``upper``), what ``export --chain`` writes for it (the controller's
interval model over the truth and its memory, nature's corners as choices), and Storm's
robust check of that file (``build_model_from_drn[stormpy.Interval]``, ``Pmin=? [F
"accept"]`` with the uncertainty resolved to the minimum) beside ``lower`` in the same
run: Storm's worst case must equal ``lower`` up to its own precision (1e-12).  Seconds:
our synthesis, the chain's construction and writing, Storm's parse and check.

Run: ``python experiments/bus_camera_band.py [--quick] [--out DIR]``.  ``--quick``: one
camera (``d = 0.5``) and one band.  Writes ``bus_camera_band.csv`` and
``bus_camera_band.md``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from typing import Any

import _common as C

from mitld_lp.running.band_chain import BAND_PROPERTY

FULL = ((0.5, (0.2, 0.4)), (0.8, (0.2, 0.4)), (0.5, (0.25, 0.35)))
QUICK = ((0.5, (0.2, 0.4)),)
PROPERTY = BAND_PROPERTY


def storm_worst(path: Any) -> tuple[float | None, float | None]:
    """Storm's worst case of :data:`PROPERTY` on the interval model at ``path`` and its
    seconds (None without stormpy)."""
    try:
        import stormpy
    except ImportError:
        return None, None
    t0 = time.perf_counter()
    model = stormpy.build_model_from_drn[stormpy.Interval](str(path))
    env = stormpy.Environment()
    env.solver().min_max().precision = stormpy.Rational("1/1000000000000")
    result = stormpy.model_checking(
        model, stormpy.parse_properties(PROPERTY)[0], environment=env,
        uncertainty_resolution_mode=stormpy.UncertaintyResolutionMode.MINIMIZE)
    return float(result.get_value(model.initial_states[0])), time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = C.out_dir(args)
    text = C.model_path("bus_puddle.toml").read_text(encoding="utf-8")
    header = ["detect", "band_b2", "status", "certified", "lower", "upper", "chain_states",
              "storm_worst", "|storm-lower|", "export_s", "storm_s"]
    rows: list[list[Any]] = []
    for d, (lo, hi) in (QUICK if args.quick else FULL):
        model = out / f"camera_d{d}_b2_{lo}_{hi}.toml"
        model.write_text(text.replace("mu2 = { geometric = 0.3 }",
                                      f"mu2 = {{ geometric = [{lo}, {hi}] }}", 1)
                         + f"\n[sensors]\nb1 = {{ detect = {d} }}\n", encoding="utf-8")
        chain = out / f"camera_d{d}_b2_{lo}_{hi}.drn"
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "mitld_lp", "export", str(model),
                               "--chain", str(chain), "--json", "--force", "-q"],
                              capture_output=True, text=True, check=False)
        t1 = time.perf_counter()
        if done.returncode not in (0, 3):
            print(f"export failed ({done.returncode}): {done.stderr.strip()}")
            return 1
        said = json.loads(done.stdout)
        states = sum(1 for line in chain.read_text().splitlines() if line.startswith("state "))
        worst, storm_s = storm_worst(chain)
        rows.append([
            d, f"[{lo}, {hi}]", said.get("status", ""), said["certified"], f"{said['lower']:.10f}",
            f"{said['upper']:.10f}", states, "" if worst is None else f"{worst:.10f}",
            "" if worst is None else f"{abs(worst - said['lower']):.1e}",
            f"{t1 - t0:.2f}", "" if storm_s is None else f"{storm_s:.2f}"])
        print(C.text_table(header, rows[-1:]), flush=True)
    print()
    print("bus_puddle, camera on b1, bus 2's law a band: the interval chain re-checked by "
          "Storm's robust engine")
    print(C.text_table(header, rows))
    C.write_tables(out, "bus_camera_band", header, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
