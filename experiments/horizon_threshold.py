"""Where the step-bounded route (``mitld_lp.routes.horizon``) starts to pay: the plain
route's product against the induction over the world, on QVBS's resource-gathering
program at growing ``B`` (``Pmax=? [F<=B "success"]``, posed as ``F[0,B] success``).

Per instance: the world's states, the product's bound (states x (B + 1)), each route's
bracket and ``synthesize`` CPU seconds (the best of ``--repeat`` runs in this process,
the kernels warmed first), the route forced by setting ``CLAIM_FROM`` (1: the
step-bounded route; past any bound: the plain one).  The answer is printed beside each
time.

    python experiments/horizon_threshold.py --qvbs /work/shared/qvbs [--quick]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

SIZES = ((20, 2, 2), (50, 4, 4), (100, 8, 8), (200, 15, 15))
QUICK = ((20, 2, 2), (50, 4, 4))


def model_file(folder: Path, prism: Path, b: int, gold: int, gem: int) -> Path:
    path = folder / f"rg-{b}-{gold}-{gem}.toml"
    path.write_text(f'name = "rg {b}-{gold}-{gem}"\nspec = "F[0,{b}] success"\n\n[prism]\n'
                    f'file = {json.dumps(str(prism))}\nconstants = {{ B = {b}, '
                    f'GOLD_TO_COLLECT = {gold}, GEM_TO_COLLECT = {gem} }}\n',
                    encoding="utf-8")
    return path


def timed(path: Path, claim_from: int, repeat: int) -> tuple[float, object]:
    from mitld_lp import load_model, synthesize
    from mitld_lp.routes import horizon

    horizon.CLAIM_FROM = claim_from
    model = load_model(path, max_states=2_000_000)
    best, r = float("inf"), None
    for _ in range(repeat):
        c = time.process_time()
        r = synthesize(model)
        best = min(best, time.process_time() - c)
    return best, r


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--qvbs", type=Path, required=True, help="the QVBS checkout")
    ap.add_argument("--quick", action="store_true", help="the two smallest sizes")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    prism = args.qvbs / "mdp" / "resource-gathering" / "resource-gathering.pm"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        warm = model_file(Path(tmp), prism, 20, 2, 2)
        timed(warm, 1, 1)
        timed(warm, 10**18, 1)
        for b, gold, gem in QUICK if args.quick else SIZES:
            path = model_file(Path(tmp), prism, b, gold, gem)
            plain_cpu, plain = timed(path, 10**18, args.repeat)
            ours_cpu, ours = timed(path, 1, args.repeat)
            states = ours.mdp.n_states
            row = dict(instance=f"{b}-{gold}-{gem}", world_states=states,
                       bound=states * (b + 1), product_states=plain.mdp.n_states,
                       plain_cpu=plain_cpu, plain=[plain.lower, plain.upper],
                       horizon_cpu=ours_cpu, horizon=[ours.lower, ours.upper])
            rows.append(row)
            print(f"{row['instance']:>12} world {states:>7,} bound {row['bound']:>11,} "
                  f"product {row['product_states']:>9,}  plain {plain_cpu:7.3f} s "
                  f"[{plain.lower:.10f}, {plain.upper:.10f}]  horizon {ours_cpu:7.3f} s "
                  f"[{ours.lower:.10f}, {ours.upper:.10f}]", flush=True)
    return rows


if __name__ == "__main__":
    main()
