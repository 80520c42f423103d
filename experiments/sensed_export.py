"""The bus case with a camera that misses bus 1 and a risk budget on the puddle, solved,
exported as a controlled chain and re-checked by Storm.

``models/bus_risk.toml`` (the bus case with two puddle cells on the direct way) with
``[sensors] b1 = { detect = d }`` and the constraint ``P(F puddle) <= bound``: the
``sensed-constrained`` route's randomised controller over information states, its
controlled chain over the truth and the controller's memory
(:mod:`mitld_lp.running.sensed_chain`, what ``export --chain`` writes), and Storm's exact
``P=? [F "accept"]`` and ``P=? [F "c1"]`` on the DRN
(``build_model_from_drn[stormpy.Rational]``) beside our certified ``lower`` and the
constraint's certified bound, in the same run: Storm's task value must be at least
``lower`` and its risk at most the bound.  Seconds: our synthesis, the chain's
construction and writing, Storm's parsing and exact check.

Run: ``python experiments/sensed_export.py [--quick] [--out DIR]``.  ``--quick``: one
camera (``d = 0.5``) and one bound (0.05).  Writes ``sensed_export.csv`` and
``sensed_export.md``.
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

FULL = ((0.5, 0.05), (0.5, 0.02), (0.8, 0.05))
QUICK = ((0.5, 0.05),)


def storm_exact(path: Any, props: list[str]) -> tuple[list[Fraction] | None, float | None]:
    """Storm's exact values of ``props`` on the DTMC at ``path`` and its seconds (None
    without stormpy)."""
    try:
        import stormpy
    except ImportError:
        return None, None
    t0 = time.perf_counter()
    model = stormpy.build_model_from_drn[stormpy.Rational](str(path))
    values = []
    for prop in props:
        result = stormpy.model_checking(model, stormpy.parse_properties(prop)[0])
        values.append(Fraction(str(result.get_value(model.initial_states[0]))))
    return values, time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    out = C.out_dir(args)
    base = load_model(C.model_path("bus_risk.toml"))
    header = ["detect", "bound", "route", "lower", "upper", "risk_certified", "chain_states",
              "storm_accept", "storm_risk", "accept>=lower", "risk<=certified", "synth_s",
              "chain_s", "storm_s"]
    rows: list[list[Any]] = []
    for d, bound in (QUICK if args.quick else FULL):
        model = dataclasses.replace(base, sensors=MappingProxyType({"b1": Sensor(d)}),
                                    constraints=(f"P(F puddle) <= {bound}",))
        t0 = time.perf_counter()
        r = synthesize(model)
        t1 = time.perf_counter()
        path = write_chain(r, out / f"chain_d{d}_b{bound}.drn", overwrite=True)
        t2 = time.perf_counter()
        states = sum(1 for line in path.read_text().splitlines() if line.startswith("state "))
        (risk,) = r.constraints
        values, storm_s = storm_exact(path, ['P=? [F "accept"]', 'P=? [F "c1"]'])
        accept, danger = values if values is not None else (None, None)
        rows.append([
            d, bound, r.route, f"{r.lower:.10f}", f"{r.upper:.10f}",
            f"{risk.certified:.10f}", states,
            "" if accept is None else f"{float(accept):.10f}",
            "" if danger is None else f"{float(danger):.10f}",
            "" if accept is None else accept >= Fraction(r.lower),
            "" if danger is None else danger <= Fraction(risk.certified),
            f"{t1 - t0:.2f}", f"{t2 - t1:.2f}", "" if storm_s is None else f"{storm_s:.2f}",
        ])
        print(C.text_table(header, rows[-1:]), flush=True)
    print()
    print("bus_risk, camera on b1, P(F puddle) <= bound: the controlled chain re-checked "
          "by Storm in exact arithmetic")
    print(C.text_table(header, rows))
    C.write_tables(out, "sensed_export", header, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
