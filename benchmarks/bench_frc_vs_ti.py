r"""Frequency-response curve of the reference gear pair: HB continuation against time integration.

Model: ``examples/paper_table1.toml`` with ``friction.model = NLTV``, ``friction.law = arctan``
(``v0 = 0.01 m/s``), the soft output spring of the example, ``H = 32``, ``N = 4096`` (the solver default).

- **HB**: the ``hbgear frc`` flow without outputs: :func:`hbgear.solve.solve_periodic` at the
  start speed, then :func:`hbgear.continuation.continuation` with
  :func:`hbgear.commands.frc.frc_method` over 3000 -> 20000 rpm, tolerance 1e-9. The first-call
  cost (start solution + JIT compilation of the residual functions) is timed apart from the
  curve; the curve is then repeated ``repeats`` times (median).
- **TI**: :func:`hbgear.simulate.simulate` (``solve_ivp`` LSODA, rtol 1e-9, from the static
  state until the DTE changes by less than 1e-6 of its peak-to-peak between periods) at a
  sample of the curve's own points (nearest to evenly spaced speeds, away from the folds), one run each
  after a warm-up run; the TI cost of the whole curve is extrapolated as (median TI time per
  point) x (points of the curve).
- **Accuracy**: at each sampled point, RMS(DTE_HB - DTE_TI) / RMS(DTE_TI - mean) over one
  steady mesh period (the waveforms themselves, not a summary number).

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
CONFIG = ROOT / "examples" / "paper_table1.toml"
OVERRIDES = ["friction.model=NLTV", "friction.law=arctan"]
H, SAMPLES, TOL = 32, 4096, 1e-9  # N = the solver default (AFT jumps alias at O(1/N))


def build():
    from hbgear.build import build_model
    from hbgear.config import load_config

    return build_model(load_config(CONFIG, OVERRIDES))


def hb_curve(model, rpm0, rpm1, repeats):
    from hbgear.commands.frc import frc_method, gear_residual_functions
    from hbgear.continuation import continuation
    from hbgear.hb import HarmonicBalance
    from hbgear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.system import GearSystem

    w0, w1 = rpm_to_rad_s(rpm0), rpm_to_rad_s(rpm1)
    a = time.perf_counter()
    start = solve_periodic(model, w0, harmonics=H, samples=SAMPLES, tolerance=TOL)
    b = time.perf_counter()
    hb, system = HarmonicBalance(model.ndof, H, 1, SAMPLES), GearSystem(model)
    rjp, res = gear_residual_functions(hb, system)
    rjp(start.z, w0)[0].block_until_ready()
    res(start.z, w0).block_until_ready()
    c = time.perf_counter()
    method = frc_method(w0, w1)
    times, branch = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        branch = continuation(rjp, res, start.z, w0, w1, method, max_points=6000, tolerance=TOL, progress=False)
        times.append(time.perf_counter() - t)
    return {
        "hb": hb, "branch": branch, "start_s": b - a, "compile_s": c - b, "first_s": c - a,
        "curve_s": statistics.median(times), "curve_all_s": times,
    }


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


def ti_compare(model, hb, branch, indices):
    from hbgear.simulate import simulate
    from hbgear.solve import PeriodicSolution

    rows = []
    try:  # warm-up (JIT of the right-hand side); a short run never reaches steady state
        simulate(model, float(branch.p[indices[0]]), max_cycles=2)
    except Exception:  # noqa: BLE001
        pass
    for i in indices:
        w = float(branch.p[i])
        a = time.perf_counter()
        tr = simulate(model, w)
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
    branch = hb["branch"]
    ti = ti_compare(model, hb["hb"], branch, sample_indices(branch, 2 if quick else 6))
    n = len(branch)
    per_point_hb = hb["curve_s"] / n
    per_point_ti = statistics.median(r["ti_s"] for r in ti)
    return {
        "range_rpm": (rpm0, rpm1 if not quick else 8000.0), "points": n, "status": branch.status.name,
        "rejected": branch.rejected, "folds_rpm": [float(x) * 60 / (2 * np.pi) for x in branch.fold_p],
        "newton_iterations": int(np.sum(branch.iterations)), "max_residual": float(np.max(branch.residual)),
        "start_s": hb["start_s"], "compile_s": hb["compile_s"], "first_s": hb["first_s"],
        "curve_s": hb["curve_s"], "curve_all_s": hb["curve_all_s"], "hb_per_point_s": per_point_hb,
        "ti_per_point_s": per_point_ti, "ti_curve_extrapolated_s": per_point_ti * n,
        "speedup_per_point": per_point_ti / per_point_hb, "ti": ti,
        "max_error": max(r["error"] for r in ti),
    }


def table(r):
    lines = [
        f"NLTV arctan, soft spring, H={H}, N={SAMPLES}: {r['range_rpm'][0]:g} -> {r['range_rpm'][1]:g} rpm, "
        f"{r['points']} points ({r['status']}, {r['rejected']} rejected steps, {r['newton_iterations']} corrector "
        f"iterations, folds at {', '.join(f'{x:.0f}' for x in r['folds_rpm']) or 'none'} rpm, max|R| {r['max_residual']:.1e})",
        f"  first curve overhead: start solution {r['start_s']:.2f} s + compile {r['compile_s']:.2f} s = {r['first_s']:.2f} s",
        f"  HB curve after compilation: {r['curve_s']:.2f} s (median of {len(r['curve_all_s'])}), "
        f"{1e3 * r['hb_per_point_s']:.1f} ms per point",
        f"  TI per point (median of {len(r['ti'])}): {r['ti_per_point_s']:.2f} s -> whole curve extrapolated "
        f"{r['ti_curve_extrapolated_s'] / 3600:.2f} h",
        f"  speed-up per point HB vs TI: {r['speedup_per_point']:.0f}x",
        "  sampled points: " + "; ".join(
            f"{t['rpm']:.0f} rpm: TI {t['ti_s']:.1f} s ({t['cycles']} cycles), DTE error {100 * t['error']:.3f} %"
            for t in r["ti"]),
        f"  max DTE waveform error HB vs TI: {100 * r['max_error']:.3f} % of the DTE RMS",
    ]
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args(argv)
    print(table(run(args.quick, args.repeats)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
