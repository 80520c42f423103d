"""The bus case with a camera on bus 2 that misses and gives false alarms, solved,
exported as a controlled chain and re-checked by Storm.

``models/bus_grid.toml`` with ``[sensors] b2 = { detect = 0.8, false_alarm = fa }``:
the ``sensed`` route on the information-state product, which with false alarms keeps
each hypothesis's count of reports before its report was due (a report or none at every
step: :mod:`mitld_lp.sensing.belief`), beside the same camera without false alarms
(``fa = 0``, the first report only) at the same ``epsilon``.  Each row: the bus's
truncation point ``T``, the product's states, the certified bracket, the seconds of the
product and the solve; then the controller's chain (what ``export --chain`` writes)
and Storm's exact ``P=? [F "accept"]`` on it (``build_model_from_drn[stormpy.Rational]``)
beside ``lower``, with Storm's seconds, in the same run.

Run: ``python experiments/false_alarms.py [--quick] [--out DIR]``.  ``--quick``:
``epsilon = 0.25`` only (``T = 4``); the full run takes ``epsilon = 0.1`` and ``0.05``
(``T = 7`` and ``9``; some minutes).
Writes ``false_alarms.csv`` and ``false_alarms.md``.
"""

from __future__ import annotations

import dataclasses
import time
from fractions import Fraction
from types import MappingProxyType
from typing import Any

import _common as C

from mitld_lp import load_model, synthesize
from mitld_lp.running.chain import write_chain
from mitld_lp.sensing import Sensor

FULL = (0.1, 0.05)
QUICK = (0.25,)
FALSE_ALARMS = (0.0, 0.05)


def storm_accept(path: Any) -> tuple[Fraction | None, float | None]:
    """Storm's exact ``P=? [F "accept"]`` on the DTMC at ``path`` and its seconds (None
    without stormpy)."""
    try:
        import stormpy
    except ImportError:
        return None, None
    t0 = time.perf_counter()
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    result = stormpy.model_checking(model, stormpy.parse_properties('P=? [F "accept"]')[0])
    return Fraction(str(result.get_value(model.initial_states[0]))), time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = C.out_dir(args)
    base = load_model(C.model_path("bus_grid.toml"))
    header = ["false_alarm", "epsilon", "T", "states", "lower", "upper", "product_s",
              "solve_s", "chain_states", "storm_accept", "storm-lower", "chain_s", "storm_s"]
    rows: list[list[Any]] = []
    for eps in (QUICK if args.quick else FULL):
        for fa in FALSE_ALARMS:
            model = dataclasses.replace(
                base, epsilon=eps, sensors=MappingProxyType({"b2": Sensor(0.8, fa)}))
            r = synthesize(model)
            t1 = time.perf_counter()
            path = write_chain(r, out / f"chain_fa{fa}_eps{eps}.drn", overwrite=True)
            t2 = time.perf_counter()
            states = sum(1 for line in path.read_text().splitlines()
                         if line.startswith("state "))
            accept, storm_s = storm_accept(path)
            rows.append([
                fa, eps, r.sta.truncation_points["b2"], r.mdp.n_states, f"{r.lower:.7f}",
                f"{r.upper:.7f}", f"{r.timings['product']:.2f}", f"{r.timings['solve']:.2f}",
                states, "" if accept is None else f"{float(accept):.10f}",
                "" if accept is None else f"{float(accept - Fraction(r.lower)):.2e}",
                f"{t2 - t1:.2f}", "" if storm_s is None else f"{storm_s:.2f}",
            ])
            print(C.text_table(header, rows[-1:]), flush=True)
    print()
    print("bus_grid, camera on b2 (detect 0.8) with and without false alarms: the sensed "
          "answer and its controlled chain re-checked by Storm in exact arithmetic")
    print(C.text_table(header, rows))
    C.write_tables(out, "false_alarms", header, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
