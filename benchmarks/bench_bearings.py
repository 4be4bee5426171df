r"""Cost of the multi-DOF gear model (MODEL.md section 10) against the 2-DOF model: per continuation
point and per Hill evaluation, H = 32, on the dense path (the reference, "before") and on the
condensed path (the system's ``input_map`` and ``output_map``, :mod:`hbgear.engine.condensed`,
"after").

Models: ``examples/bearings.toml`` without ``[bearings]`` (2 DOF), as given (6 DOF) and with the
``[shafts]`` of ``tests/test_bearings.py`` (8 DOF), each in LTV-A (linear: one solve per point) and
NLTV-A (arctan law; Newton per point). Per point: the compiled continuation (the ``frc``
command's sweep method) from 4000 rpm to ``stop`` from zero harmonics, the time after the start
point over the points after it; once to compile, then ``repeats`` rounds in which every
(model, path) takes its turn (the machine's load drifts). The 2-DOF model has nothing to condense
(both paths are dense). Per Hill evaluation: :func:`hbgear.engine.floquet.hill_multipliers` at
5000 rpm on the solution there (dense matrices on both paths), after one compiling call.
Medians; ratios to the 2-DOF model of the same run.

Run as a script, the process is set up as the ``hbgear`` command sets it up
(:func:`hbgear.runtime.configure` before JAX starts: one XLA thread, one BLAS thread; ``run.py``
calls :func:`run` in its own process as it is); ``--library-defaults`` leaves JAX's thread pool and
the BLAS threads as the libraries set them, and ``--blas-threads N`` then sets
``OPENBLAS_NUM_THREADS`` (and the OpenMP/MKL equivalents) before numpy is imported: on a shared
2-core machine the multi-threaded LAPACK factorisations above ~300 unknowns (the dense path's
LU, Hill's eigenvalues) can be slower by one or two orders of magnitude than with one thread.
Besides the ratio per point, the table gives the ratio per curve (the whole range: the 8-DOF
curve takes fewer, larger steps).

Run: ``python benchmarks/bench_bearings.py [--quick] [--library-defaults [--blas-threads 1]]``.
"""

from __future__ import annotations

import argparse
import os
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
SAMPLES = 1024
START_RPM = 4000.0


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


class Curve:
    """One (model, path): the continuation's functions, prepared once."""

    def __init__(self, model, operator, stop_rpm):
        from hbgear.engine.hb import HarmonicBalance, residual_functions
        from hbgear.gear.solve import rpm_to_rad_s
        from hbgear.gear.system import GearSystem

        self.hb = HarmonicBalance(model.ndof, HARMONICS, 1, SAMPLES, operator=operator)
        self.functions = residual_functions(self.hb, GearSystem(model))
        self.condensed = self.functions[2][1].condensed is not None
        self.range = rpm_to_rad_s(START_RPM), rpm_to_rad_s(stop_rpm)

    def per_point(self):
        import numpy as np

        from hbgear.engine.continuation import Status, continuation, sweep_method

        rj, r, args = self.functions
        p0, p1 = self.range
        t0 = time.perf_counter()
        branch = continuation(rj, r, np.zeros(self.hb.size), p0, p1, sweep_method(p0, p1, None), args=args,
                              progress=False)
        elapsed = time.perf_counter() - t0 - branch.start_seconds
        assert branch.status == Status.SUCCESS, branch.message
        return elapsed / max(len(branch.p) - 1, 1), len(branch.p)


def _hill_time(model, repeats):
    from hbgear.engine import floquet
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem

    w = rpm_to_rad_s(5000.0)
    sol = solve_periodic(model, w, harmonics=HARMONICS, samples=SAMPLES)
    hb, system = HarmonicBalance(model.ndof, HARMONICS, 1, SAMPLES), GearSystem(model)
    floquet.hill_multipliers(hb, sol.z, w, system)  # compile
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        floquet.hill_multipliers(hb, sol.z, w, system)
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def run(quick: bool = False) -> dict:
    repeats = 3 if quick else 5  # medians of 3 or 5: the first round after compiling can be slow
    stop = 4600.0 if quick else 5500.0
    results = {}
    for coupling in ("LTV", "NLTV"):
        ms = models(coupling)
        curves = {}
        for dof, m in ms.items():
            for operator in ("dense", "auto"):
                curve = Curve(m, operator, stop)
                if dof == 2 and operator == "auto":
                    assert not curve.condensed  # nothing to condense: the dense path
                    continue
                curve.per_point()  # compile
                curves[dof, operator] = curve
        times = {key: [] for key in curves}
        points = {}
        for _ in range(repeats):
            for key, curve in curves.items():
                t, n = curve.per_point()
                times[key].append(t)
                points[key] = n
        med = {key: statistics.median(v) for key, v in times.items()}
        med[2, "auto"] = med[2, "dense"]
        points[2, "auto"] = points[2, "dense"]
        hill = {dof: _hill_time(m, repeats) for dof, m in ms.items()}
        results[coupling] = {"per_point_s": med, "points": points, "hill_s": hill,
                             "point_ratio": {key: med[key] / med[2, "dense"] for key in med},
                             # the whole range (the points after the start): per point times points
                             "curve_ratio": {d: med[d, "auto"] * (points[d, "auto"] - 1)
                                             / (med[2, "dense"] * (points[2, "dense"] - 1)) for d in ms},
                             "hill_ratio": {d: hill[d] / hill[2] for d in ms},
                             "condensed": {key: curve.condensed for key, curve in curves.items()}}
        print(f"{coupling}: " + "; ".join(f"{d} DOF {op} {1e3 * med[d, op]:.2f} ms/point ({points[d, op]} points)"
                                          for d, op in sorted(med)), flush=True)
    return results


def table(results: dict) -> str:
    lines = [f"{'coupling':8s} {'DOF':>4s} {'dense ms/pt':>11s} {'x 2-DOF':>8s} {'auto ms/pt':>10s} {'x 2-DOF':>8s} "
             f"{'points':>6s} {'curve x':>8s} {'Hill ms':>8s} {'x 2-DOF':>8s}"]
    for coupling, r in results.items():
        for d in (2, 6, 8):
            lines.append(f"{coupling:8s} {d:4d} {1e3 * r['per_point_s'][d, 'dense']:11.2f} "
                         f"{r['point_ratio'][d, 'dense']:8.2f} {1e3 * r['per_point_s'][d, 'auto']:10.2f} "
                         f"{r['point_ratio'][d, 'auto']:8.2f} {r['points'][d, 'auto']:6d} {r['curve_ratio'][d]:8.2f} "
                         f"{1e3 * r['hill_s'][d]:8.1f} {r['hill_ratio'][d]:8.2f}")
    return "\n".join(lines)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--blas-threads", type=int, default=None,
                        help="OPENBLAS/OMP/MKL threads, set before numpy is imported (default: the library's)")
    parser.add_argument("--library-defaults", action="store_true",
                        help="JAX's thread pool and the BLAS threads as the libraries set them, not as the hbgear "
                             "command runs")
    args = parser.parse_args()
    if args.blas_threads is not None:
        if not args.library_defaults:
            parser.error("--blas-threads goes with --library-defaults (the hbgear runtime uses one BLAS thread)")
        for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ[name] = str(args.blas_threads)
    if not args.library_defaults:
        from hbgear import runtime

        print("# runtime:", runtime.configure(), flush=True)
    print(table(run(args.quick)))
