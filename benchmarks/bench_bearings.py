r"""Cost of the multi-DOF gear model (MODEL.md section 10) against the 2-DOF model: per continuation
point and per Hill evaluation, H = 32.

Models: ``examples/bearings.toml`` without ``[bearings]`` (2 DOF), as given (6 DOF) and with the
``[shafts]`` of ``tests/test_bearings.py`` (8 DOF), each in LTV-A (linear: one solve per point) and
NLTV-A (arctan law; Newton per point). Per point: a curve 4000 -> 7000 rpm without stability
(``timings_s["continuation"]`` over its points), once to compile, then ``repeats`` times, the
models taking turns within each round (the machine's load drifts); per Hill evaluation:
:func:`hbgear.engine.floquet.hill_multipliers` at 5000 rpm on the solution there, after one
compiling call. Medians; ratios to the 2-DOF model of the same round set.

Run: ``python benchmarks/bench_bearings.py [--quick]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # measure this checkout, not an installed hbgear
CONFIG = ROOT / "examples" / "bearings.toml"
SHAFTS = dict(drive_inertia_kgm2=5e-3, load_inertia_kgm2=1e-2, drive_stiffness_Nm_per_rad=2e5,
              load_stiffness_Nm_per_rad=3e5, damping_ratio=0.02)
HARMONICS = 32


def models(coupling: str):
    from hbgear import build_model
    from hbgear.config import parse_config, read_toml

    out = {}
    for dof in (2, 6, 8):
        data = read_toml(CONFIG)
        data["friction"] |= {"model": coupling} | ({"law": "arctan"} if coupling == "NLTV" else {})
        if dof == 2:
            del data["bearings"]
        if dof == 8:
            data["shafts"] = dict(SHAFTS)
        out[dof] = build_model(parse_config(data))
    return out


def _curve_per_point(model, start_rpm, stop_rpm):
    from hbgear.gear.response import frequency_response
    from hbgear.gear.solve import rpm_to_rad_s

    curve = frequency_response(model, rpm_to_rad_s(start_rpm), rpm_to_rad_s(stop_rpm), harmonics=HARMONICS,
                               samples=1024, stability=False, progress=False)
    return curve.timings_s["continuation"] / max(curve.points - 1, 1), curve.points


def _hill_time(model, repeats):
    from hbgear.engine import floquet
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem

    w = rpm_to_rad_s(5000.0)
    sol = solve_periodic(model, w, harmonics=HARMONICS, samples=1024)
    hb, system = HarmonicBalance(model.ndof, HARMONICS, 1, 1024), GearSystem(model)
    floquet.hill_multipliers(hb, sol.z, w, system)  # compile
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        floquet.hill_multipliers(hb, sol.z, w, system)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def run(quick: bool = False) -> dict:
    repeats = 2 if quick else 3
    stop = 5500.0 if quick else 7000.0
    results = {}
    for coupling in ("LTV", "NLTV"):
        ms = models(coupling)
        for dof, m in ms.items():
            _curve_per_point(m, 4000.0, 4300.0)  # compile
        per_point = {dof: [] for dof in ms}
        points = {}
        for _ in range(repeats):
            for dof, m in ms.items():
                t, n = _curve_per_point(m, 4000.0, stop)
                per_point[dof].append(t)
                points[dof] = n
        hill = {dof: _hill_time(m, repeats) for dof, m in ms.items()}
        med = {dof: statistics.median(v) for dof, v in per_point.items()}
        results[coupling] = {"per_point_s": med, "points": points, "hill_s": hill,
                             "point_ratio": {d: med[d] / med[2] for d in ms},
                             "hill_ratio": {d: hill[d] / hill[2] for d in ms}}
        print(f"{coupling}: " + "; ".join(f"{d} DOF {1e3 * med[d]:.2f} ms/point ({points[d]} points), Hill "
                                          f"{1e3 * hill[d]:.1f} ms" for d in ms), flush=True)
    return results


def table(results: dict) -> str:
    lines = [f"{'coupling':8s} {'DOF':>4s} {'ms/point':>9s} {'x 2-DOF':>8s} {'Hill ms':>8s} {'x 2-DOF':>8s}"]
    for coupling, r in results.items():
        for d in (2, 6, 8):
            lines.append(f"{coupling:8s} {d:4d} {1e3 * r['per_point_s'][d]:9.2f} {r['point_ratio'][d]:8.2f} "
                         f"{1e3 * r['hill_s'][d]:8.1f} {r['hill_ratio'][d]:8.2f}")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    print(table(run(args.quick)))
