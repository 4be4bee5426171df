r"""Frequency-response curve of the reference gear pair: HB continuation against time integration.

Model: ``examples/paper_table1.toml`` with ``friction.model = NLTV``, ``friction.law = arctan``
(``v0 = 0.01 m/s``), the soft output spring of the example, ``H = 32``, ``N`` = the solver default
(1024 AFT samples, jump-corrected).

- **HB**: the ``hbgear frc`` flow without outputs: :func:`hbgear.engine.continuation.continuation`
  from :func:`hbgear.gear.solve.start_guess` (the quasi-static state, corrected at the start speed
  inside the compiled corrector) with :func:`hbgear.engine.continuation.sweep_method` (the compiled
  chord corrector) over 3000 -> 20000 rpm, tolerance 1e-9. The first run compiles the
  corrector; the curve is then repeated ``repeats`` times (median). First-curve overhead =
  first run - median run (``Branch.start_seconds`` of the first run: compilation + start);
  the same is measured in ``COLD_PROCESSES`` fresh Python processes, each with a new empty
  disk cache (``--first-curve ... --cold``), and the headline is the median of all of them.
  Then, in a fresh Python process sharing the disk cache, the first curve of **another gear
  pair** (torque x 1.3, mesh damping x 1.5): its parameters are arguments of the compiled
  program, so it loads from the cache instead of compiling (``--first-curve``).
- **TI**: :func:`hbgear.gear.simulate.simulate` (``solve_ivp`` LSODA from the static state until the
  DTE changes by less than ``steady_tolerance`` of its peak-to-peak between periods) at two
  tolerances: ``rtol 1e-9`` (steady 1e-6, the default) and ``rtol 1e-6`` (steady 1e-4), at a
  sample of the curve's own points (nearest to evenly spaced speeds, away from the folds), one
  run each after a warm-up run; the TI cost of the whole curve is extrapolated as (median TI
  time per point) x (points of the curve).
- **Accuracy**: at each sampled point, RMS(DTE_HB - DTE_TI) / RMS(DTE_TI - mean) over one
  steady mesh period (the waveforms themselves, not a summary number), for each TI tolerance.

Run: ``python benchmarks/bench_frc_vs_ti.py [--quick]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # measure this checkout, not an installed hbgear
CONFIG = ROOT / "examples" / "paper_table1.toml"
OVERRIDES = ["friction.model=NLTV", "friction.law=arctan"]
H, TOL = 32, 1e-9


def _default_samples():
    from hbgear.config import SolverConfig

    return SolverConfig().time_samples


SAMPLES = _default_samples()  # N = the solver default


def build():
    from hbgear.build import build_model
    from hbgear.config import load_config

    return build_model(load_config(CONFIG, OVERRIDES))


TI_SETTINGS = ((1e-9, 1e-6), (1e-6, 1e-4))  # (rtol, steady_tolerance) of the two TI runs


def hb_method(w0, w1):
    from hbgear.engine.continuation import sweep_method

    return sweep_method(w0, w1)  # the compiled chord corrector, as `hbgear frc` runs it


def hb_curve(model, rpm0, rpm1, repeats):
    from hbgear.engine.hb import residual_functions
    from hbgear.engine.continuation import continuation
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.solve import rpm_to_rad_s, start_guess
    from hbgear.gear.system import GearSystem

    w0, w1 = rpm_to_rad_s(rpm0), rpm_to_rad_s(rpm1)
    hb, system = HarmonicBalance(model.ndof, H, 1, SAMPLES), GearSystem(model)
    rjp, res, fixed = residual_functions(hb, system)
    z0 = start_guess(model, hb, system)
    method = hb_method(w0, w1)
    times, starts, branch = [], [], None
    for _ in range(repeats + 1):  # the first run compiles the corrector
        t = time.perf_counter()
        branch = continuation(rjp, res, z0, w0, w1, method, max_points=6000, tolerance=TOL, progress=False,
                              args=fixed)
        times.append(time.perf_counter() - t)
        starts.append(branch.start_seconds)
    curve = statistics.median(times[1:])
    return {
        "hb": hb, "branch": branch, "start_s": starts[0], "start_warm_s": statistics.median(starts[1:]),
        "first_s": times[0] - curve, "first_curve_s": times[0], "curve_s": curve, "curve_all_s": times[1:],
    }


#: Fresh processes with an empty disk cache that measure the first-curve overhead again (the
#: compile time on a shared 2-core machine varies by a second from run to run).
COLD_PROCESSES = 2


def new_pair_first_curve(rpm0, rpm1, cold=False):
    """The first curve in a fresh process: of another gear pair sharing the disk cache, or
    (`cold`) of the same pair with a new empty disk cache. Its overhead, as :func:`hb_curve`."""
    import json
    import os
    import shutil
    import subprocess
    import tempfile

    env = dict(os.environ)
    cache = tempfile.mkdtemp(prefix="hbgear-bench-cold-") if cold else None
    if cold:
        env["HBGEAR_CACHE_DIR"] = cache
    try:
        out = subprocess.run([sys.executable, __file__, "--first-curve", str(rpm0), str(rpm1)]
                             + (["--cold"] if cold else []), capture_output=True, text=True, check=True, env=env)
    finally:
        if cache:
            shutil.rmtree(cache, ignore_errors=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _first_curve_main(rpm0, rpm1, cold=False):
    import json

    model = build()
    if not cold:
        model = model.replace(torque_pinion_Nm=1.3 * model.torque_pinion_Nm, damping_ratio=1.5 * model.damping_ratio)
    r = hb_curve(model, rpm0, rpm1, 1)
    print(json.dumps({"first_s": r["first_s"], "start_s": r["start_s"], "first_curve_s": r["first_curve_s"],
                      "points": len(r["branch"])}))


def sample_indices(branch, count):
    """``count`` branch points evenly spread by index, excluding the stretch between folds."""
    p = np.asarray(branch.p)
    bad = np.zeros(len(p), dtype=bool)
    folds = list(branch.folds)
    if folds:
        lo, hi = p[folds].min(), p[folds].max()
        bad |= (p >= lo * 0.98) & (p <= hi * 1.02)
    good = np.flatnonzero(~bad)
    targets = np.linspace(p.min(), p.max(), count + 2)[1:-1]  # evenly spread in speed
    return np.array([good[np.argmin(np.abs(p[good] - t))] for t in targets])


def ti_compare(model, hb, branch, indices, rtol, steady_tolerance):
    from hbgear.gear.simulate import simulate
    from hbgear.gear.solve import PeriodicSolution

    rows = []
    try:  # warm-up (JIT of the right-hand side); a short run never reaches steady state
        simulate(model, float(branch.p[indices[0]]), max_cycles=2, rtol=rtol)
    except Exception:  # noqa: BLE001
        pass
    for i in indices:
        w = float(branch.p[i])
        a = time.perf_counter()
        tr = simulate(model, w, rtol=rtol, steady_tolerance=steady_tolerance)
        elapsed = time.perf_counter() - a
        sol = PeriodicSolution.from_z(model, w, branch.z[i], hb)
        s = np.asarray(tr.s) % 1.0
        q_hb = sol.state_at(s)[0][0]
        q_ti = np.asarray(tr.q[0])
        err = float(np.sqrt(np.mean((q_hb - q_ti) ** 2)) / np.sqrt(np.mean((q_ti - q_ti.mean()) ** 2)))
        rows.append({"rpm": w * 60 / (2 * np.pi), "ti_s": elapsed, "cycles": tr.cycles, "error": err,
                     "period_cycles": tr.period_cycles})
    return rows


def run(quick=False, repeats=None):
    repeats = repeats or (1 if quick else 2)
    rpm0, rpm1 = (3000.0, 20000.0)
    model = build()
    hb = hb_curve(model, rpm0, rpm1 if not quick else 8000.0, repeats)
    other = new_pair_first_curve(rpm0, rpm1 if not quick else 8000.0)
    cold = [new_pair_first_curve(rpm0, rpm1 if not quick else 8000.0, cold=True) for _ in range(COLD_PROCESSES)]
    first_all = [hb["first_s"]] + [c["first_s"] for c in cold]
    branch = hb["branch"]
    indices = sample_indices(branch, 2 if quick else 6)
    n = len(branch)
    per_point_hb = hb["curve_s"] / n
    tis = []
    for rtol, steady in TI_SETTINGS:
        rows = ti_compare(model, hb["hb"], branch, indices, rtol, steady)
        per_point_ti = statistics.median(r["ti_s"] for r in rows)
        tis.append({"rtol": rtol, "steady": steady, "rows": rows, "per_point_s": per_point_ti,
                    "curve_extrapolated_s": per_point_ti * n, "speedup_per_point": per_point_ti / per_point_hb,
                    "max_error": max(r["error"] for r in rows)})
    return {
        "range_rpm": (rpm0, rpm1 if not quick else 8000.0), "points": n, "status": branch.status.name,
        "rejected": branch.rejected, "folds_rpm": [float(x) * 60 / (2 * np.pi) for x in branch.fold_p],
        "newton_iterations": int(np.sum(branch.iterations)), "max_residual": float(np.max(branch.residual)),
        "start_s": hb["start_s"], "start_warm_s": hb["start_warm_s"], "first_s": statistics.median(first_all),
        "first_all_s": first_all,
        "first_curve_s": hb["first_curve_s"], "curve_s": hb["curve_s"], "curve_all_s": hb["curve_all_s"],
        "new_pair": other,
        "hb_per_point_s": per_point_hb, "ti": tis,
        # the headline numbers: against the tight TI (the reference waveform)
        "ti_per_point_s": tis[0]["per_point_s"], "speedup_per_point": tis[0]["speedup_per_point"],
        "max_error": tis[0]["max_error"],
    }


def table(r):
    lines = [
        f"NLTV arctan, soft spring, H={H}, N={SAMPLES}: {r['range_rpm'][0]:g} -> {r['range_rpm'][1]:g} rpm, "
        f"{r['points']} points ({r['status']}, {r['rejected']} rejected steps, {r['newton_iterations']} corrector "
        f"iterations, folds at {', '.join(f'{x:.0f}' for x in r['folds_rpm']) or 'none'} rpm, max|R| {r['max_residual']:.1e})",
        f"  first curve: {r['first_curve_s']:.2f} s in all; overhead (first run - median run) {r['first_all_s'][0]:.2f} s "
        f"(compilation + start point {r['start_s']:.2f} s; the start point alone, compiled: {r['start_warm_s']:.3f} s)",
        f"  first-curve overhead again in {len(r['first_all_s']) - 1} fresh processes, each with an empty disk cache: "
        + ", ".join(f"{x:.2f} s" for x in r["first_all_s"][1:])
        + f"; median of all {len(r['first_all_s'])}: {r['first_s']:.2f} s",
        f"  first curve of another gear pair (torque x 1.3, damping x 1.5) in a fresh process, same disk cache: "
        f"overhead {r['new_pair']['first_s']:.2f} s (start point + loading the compiled program "
        f"{r['new_pair']['start_s']:.2f} s), {r['new_pair']['points']} points",
        f"  HB curve after compilation: {r['curve_s']:.2f} s (median of {len(r['curve_all_s'])}), "
        f"{1e3 * r['hb_per_point_s']:.2f} ms per point",
    ]
    for ti in r["ti"]:
        lines += [
            f"  TI rtol {ti['rtol']:.0e} (steady {ti['steady']:.0e}), per point (median of {len(ti['rows'])}): "
            f"{ti['per_point_s']:.2f} s -> whole curve extrapolated {ti['curve_extrapolated_s'] / 3600:.2f} h; "
            f"HB vs this TI per point: {ti['speedup_per_point']:.0f}x",
            "    sampled points: " + "; ".join(
                f"{t['rpm']:.0f} rpm: TI {t['ti_s']:.1f} s ({t['cycles']} cycles), DTE HB-TI {100 * t['error']:.3f} %"
                for t in ti["rows"]),
            f"    max DTE waveform difference HB vs this TI: {100 * ti['max_error']:.3f} % of the DTE RMS",
        ]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--first-curve", nargs=2, type=float, metavar=("RPM0", "RPM1"),
                        help="only the first curve of another gear pair (JSON on the last line)")
    parser.add_argument("--cold", action="store_true",
                        help="with --first-curve: the same gear pair (the caller gives an empty disk cache)")
    args = parser.parse_args(argv)
    if args.first_curve:
        _first_curve_main(*args.first_curve, cold=args.cold)
        return 0
    print(table(run(args.quick, args.repeats)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
