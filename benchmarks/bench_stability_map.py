r"""Stability maps: exact monodromy for LTV-A, Hill's method for NLTV.

- **LTV-A map**: :func:`hbgear.gear.maps.stability_map_ltv_a` on ``examples/paper_table1.toml``
  (its own LTV formulation-A friction), 100 speeds (20000 -> 32000 rpm) x 50 contact ratios
  (1.35 -> 1.65); one warm-up call on a 2 x 2 grid, then the full map ``repeats`` times (median).
  The models (one per contact ratio) are built inside the timed call, as ``hbgear
  stability-map`` does.
- **NLTV Hill map**: :func:`hbgear.gear.maps.stability_map` with ``friction.model = NLTV``,
  ``law = arctan``, ``H = 32`` on a small grid (harmonic balance at each point, warm-started
  along the speeds, then Hill's method batched over the row); per-point time, after one compiling
  call on one row of the grid's length (the batched Hill is compiled for its batch size). A second timing splits one point into
  its HB solve and its Hill step, the latter both ways: ``method="refined"`` (the default at
  this size: central eigenpairs only) and ``method="dense"`` (the full companion
  eigen-decomposition), with the largest difference of their multipliers.

Run: ``python benchmarks/bench_stability_map.py [--quick]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from bench_duffing_tools import max_pair_distance  # same directory: on sys.path as a script and from run.py

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "paper_table1.toml"


def run(quick=False, repeats=None):
    from hbgear.config import load_config
    from hbgear import stability_map
    from hbgear.build import model_at_contact_ratio
    from hbgear.gear.maps import stability_map_ltv_a

    repeats = repeats or (2 if quick else 5)
    cfg = load_config(CONFIG, [])
    speeds = np.linspace(20000.0, 32000.0, 100)
    ratios = np.linspace(1.35, 1.65, 50)
    a = time.perf_counter()
    stability_map_ltv_a([model_at_contact_ratio(cfg, g) for g in ratios[:2]], speeds[:2])
    first = time.perf_counter() - a
    times = []
    for _ in range(repeats):
        a = time.perf_counter()
        grid = stability_map_ltv_a([model_at_contact_ratio(cfg, g) for g in ratios], speeds)
        times.append(time.perf_counter() - a)
    out = {"ltv_first_s": first, "ltv_map_s": statistics.median(times), "ltv_shape": grid.shape,
           "ltv_unstable_share": float(np.mean(grid > 1 + 1e-9)), "ltv_repeats": repeats}

    # NLTV, Hill's method on a small grid
    ncfg = load_config(CONFIG, ["friction.model=NLTV", "friction.law=arctan", "solver.harmonics=32"])
    n_speeds, n_ratios = (4, 1) if quick else (10, 3)
    nspeeds = np.linspace(20000.0, 32000.0, n_speeds)
    nratios = np.linspace(1.35, 1.65, n_ratios)
    a = time.perf_counter()
    # compile: one row of the grid's length (the row's batched Hill is compiled for its batch size)
    stability_map(ncfg, nspeeds, nratios[:1])
    out["nltv_first_s"] = time.perf_counter() - a
    a = time.perf_counter()
    ngrid = stability_map(ncfg, nspeeds, nratios)
    elapsed = time.perf_counter() - a
    out.update(nltv_shape=ngrid.shape, nltv_s=elapsed, nltv_per_point_s=elapsed / ngrid.size,
               nltv_nan=int(np.sum(~np.isfinite(ngrid))))

    # one point split: HB solve (cold start from the LTV solution, as the map's first speed) vs Hill
    from hbgear.build import build_model
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.gear.system import GearSystem

    model = build_model(ncfg)
    w = rpm_to_rad_s(26000.0)
    hb = HarmonicBalance(model.ndof, 32, 1, 256)
    system = GearSystem(model)
    t_hb, t_hill, t_dense, diff = [], [], [], []
    for _ in range(3):
        a = time.perf_counter()
        sol = solve_periodic(model, w, harmonics=32, samples=256)
        b = time.perf_counter()
        fast = hill_multipliers(hb, sol.z, w, system, method="refined")
        c = time.perf_counter()
        dense = hill_multipliers(hb, sol.z, w, system, method="dense")
        t_hb.append(b - a)
        t_hill.append(c - b)
        t_dense.append(time.perf_counter() - c)
        diff.append(float(max_pair_distance(fast, dense, relative=True)))
    out["point_hb_s"], out["point_hill_s"] = statistics.median(t_hb), statistics.median(t_hill)
    out["point_hill_dense_s"], out["point_hill_rel_diff"] = statistics.median(t_dense), max(diff)
    return out


def table(r):
    n = r["ltv_shape"][0] * r["ltv_shape"][1]
    return "\n".join([
        f"LTV-A exact monodromy map {r['ltv_shape'][1]} speeds x {r['ltv_shape'][0]} contact ratios: "
        f"{r['ltv_map_s']:.3f} s (median of {r['ltv_repeats']}; {1e6 * r['ltv_map_s'] / n:.0f} us per point; "
        f"first call on 2x2 {r['ltv_first_s']:.2f} s; {100 * r['ltv_unstable_share']:.1f} % unstable)",
        f"NLTV Hill map {r['nltv_shape'][1]} speeds x {r['nltv_shape'][0]} contact ratios (H=32): {r['nltv_s']:.2f} s, "
        f"{1e3 * r['nltv_per_point_s']:.0f} ms per point ({r['nltv_nan']} not converged; first call, one row (compiling) "
        f"{r['nltv_first_s']:.2f} s)",
        f"  one NLTV point from scratch: HB solve {1e3 * r['point_hb_s']:.0f} ms + Hill {1e3 * r['point_hill_s']:.1f} ms "
        f"(refined; dense {1e3 * r['point_hill_dense_s']:.1f} ms, {r['point_hill_dense_s'] / r['point_hill_s']:.1f}x; "
        f"max relative difference of the multipliers {r['point_hill_rel_diff']:.1e})",
    ])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args(argv)
    print(table(run(args.quick, args.repeats)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
