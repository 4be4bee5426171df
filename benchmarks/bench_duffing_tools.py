r"""Duffing frequency response: hbgear against other Python harmonic-balance tools.

Problem: ``x'' + 0.02 x' + x + 0.1 x^3 = 0.05 cos(w t)``, ``w`` in ``[0.5, 2]`` [rad/s],
``H = 7`` harmonics, ``N = 64`` time samples per period (AFT) for every tool.

- **hbgear**: :func:`hbgear.engine.continuation.continuation` on :class:`hbgear.engine.system.Duffing`,
  Newton tolerance ``1e-9`` on ``max |R|``, then Hill's method on every point, timed
  separately: batched over the curve (:func:`hbgear.engine.floquet.hill_multipliers_batch`, as
  ``hbgear frc`` does) and, for the ratio, one :func:`hbgear.engine.floquet.hill_multipliers` call
  per point.
- **pyHarm** (PyPI ``pyharm-os``): installed into its own virtual environment
  ``benchmarks/.venv-others`` (created on first use with ``python3 -m venv`` and ``pip``),
  run in a subprocess of that interpreter (this file, ``--pyharm-worker``): its ``frf`` analysis
  (tangent predictor, arc-length corrector) with its own Newton-Raphson solver at
  ``tol_residual = 1e-9``, and with its default ``scipyroot`` solver (residual tolerance 1e-4).
- **Reference**: a long time integration (``scipy.integrate.solve_ivp``, DOP853,
  ``rtol = 1e-11``) from rest at frequencies outside the bistable band; the error of each tool
  is the RMS difference of one steady period, relative to the RMS of the TI waveform.

Timings are the median of ``repeats`` runs after a first, compiling, run (reported apart).

Run: ``python benchmarks/bench_duffing_tools.py [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
OTHERS_VENV = HERE / ".venv-others"
H, SAMPLES, W0, W1 = 7, 64, 0.5, 2.0
DAMPING, STIFFNESS, CUBIC, FORCING = 0.02, 1.0, 0.1, 0.05
TOLERANCE = 1e-9
CHECK_W = (0.6, 0.8, 0.95, 1.3, 1.6, 1.9)  # single-valued response (the bistable band is ~1.05-1.16)


def max_pair_distance(a, b, relative=False):
    """Largest distance between two sets of multipliers paired one to one (the closest pairing)."""
    from scipy.optimize import linear_sum_assignment

    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape:
        return float("inf")
    d = np.abs(a[:, None] - b[None, :])
    if relative:
        d = d / np.maximum(np.abs(b)[None, :], 1e-300)
    rows, cols = linear_sum_assignment(d)
    return float(d[rows, cols].max(initial=0.0))


# ----------------------------------------------------------------------------- reference
def duffing_ti(w, periods=None):
    """Steady waveform ``x(tau)`` on ``SAMPLES`` points of one period, by a long integration."""
    from scipy.integrate import solve_ivp

    period = 2 * np.pi / w
    periods = periods or int(max(200, np.ceil(1500.0 / period)))  # decay time 1/0.01 = 100 s

    def rhs(t, y):
        return [y[1], FORCING * np.cos(w * t) - DAMPING * y[1] - STIFFNESS * y[0] - CUBIC * y[0] ** 3]

    t_end = periods * period
    tau = np.arange(SAMPLES) / SAMPLES
    sol = solve_ivp(rhs, (0.0, t_end), [0.0, 0.0], method="DOP853", rtol=1e-11, atol=1e-13,
                    t_eval=t_end - period + tau * period)
    return sol.y[0]


def waveform(coeffs, harmonics=H):
    """``x(tau_j)`` from real coefficients ``[a0, a1, b1, ...]`` (cos/sin of k w t)."""
    tau = 2 * np.pi * np.arange(SAMPLES) / SAMPLES
    k = np.arange(1, harmonics + 1)
    return coeffs[0] + coeffs[1::2] @ np.cos(np.outer(k, tau)) + coeffs[2::2] @ np.sin(np.outer(k, tau))


_TI_CACHE: dict = {}


def branch_error(ws, coeffs, checks):
    """Max over `checks` of RMS(x_tool - x_TI) / RMS(x_TI), at the tool's own stored point nearest
    each check frequency (TI run at that exact ``w``): no interpolation between points."""
    errors = []
    ws = np.asarray(ws)
    for w in checks:
        i = int(np.argmin(np.abs(ws - w)))
        key = round(float(ws[i]), 12)
        if key not in _TI_CACHE:
            _TI_CACHE[key] = duffing_ti(float(ws[i]))
        ref = _TI_CACHE[key]
        x = waveform(np.asarray(coeffs[i]))
        errors.append(float(np.sqrt(np.mean((x - ref) ** 2)) / np.sqrt(np.mean(ref**2))))
    return max(errors)


# ----------------------------------------------------------------------------- hbgear
def run_hbgear(repeats, ds_max=0.05):
    import jax.numpy as jnp

    from hbgear.engine.continuation import PseudoArclength, continuation
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.floquet import hill_multipliers, hill_multipliers_batch, is_stable
    from hbgear.engine.system import Duffing

    t0 = time.perf_counter()
    hb = HarmonicBalance(1, H, 1, SAMPLES)
    system = Duffing(DAMPING, STIFFNESS, CUBIC, FORCING)

    def rjp(z, p):
        return hb.residual_and_jacobians(jnp.asarray(z), p, system)

    def res(z, p):
        return hb.residual(jnp.asarray(z), p, system)

    method = PseudoArclength(ds=0.01, ds_min=1e-7, ds_max=ds_max, max_angle_deg=10.0, parameter_scale=W1, jit_step=True)

    def curve():
        return continuation(rjp, res, np.zeros(hb.size), W0, W1, method, max_points=5000,
                            tolerance=TOLERANCE, progress=False)

    def hill(branch):
        return hill_multipliers_batch(hb, np.asarray(branch.z), np.asarray(branch.p), system)

    def hill_per_point(branch):
        return [hill_multipliers(hb, branch.z[i], float(branch.p[i]), system) for i in range(len(branch))]

    branch = curve()
    multipliers = hill(branch)
    hill_per_point(branch)
    first = time.perf_counter() - t0
    t_curve, t_hill, t_single = [], [], []
    for _ in range(repeats):
        a = time.perf_counter()
        branch = curve()
        b = time.perf_counter()
        multipliers = hill(branch)
        c = time.perf_counter()
        single = hill_per_point(branch)
        t_curve.append(b - a)
        t_hill.append(c - b)
        t_single.append(time.perf_counter() - c)
    same = max(float(max_pair_distance(m, s)) for m, s in zip(multipliers, single))
    stable = np.array([is_stable(m) for m in multipliers])
    return {
        "tool": "hbgear",
        "points": len(branch),
        "status": branch.status.name,
        "first_run_s": first,
        "curve_s": statistics.median(t_curve),
        "hill_s": statistics.median(t_hill),
        "hill_per_point_call_s": statistics.median(t_single),
        "hill_batch_vs_single_max_diff": same,
        "unstable_points": int(np.sum(~stable)),
        "w": np.asarray(branch.p).tolist(),
        "coeffs": np.asarray(branch.z).tolist(),
        "max_residual": float(np.max(branch.residual)),
    }


# ----------------------------------------------------------------------------- pyHarm
def pyharm_input(solver, tol):
    solver_options = {"tol_residual": tol, "tol_delta_x": 1e-12, "max_iter": 50} if solver == "NewtonRaphson" else {}
    return {
        "export": {"status": False},
        "system": {"type": "Base", "nh": H, "nti": SAMPLES},
        "substructures": {"sub": {"type": "onlydofs", "nnodes": 1, "ndofs": 1, "nmodes": 0, "matching": [0]}},
        "connectors": {
            "mass": {"type": "GOElement", "connect": {"sub": [0]}, "dirs": [0], "dto": 2, "xo": 1, "k": 1.0},
            "damper": {"type": "LinearDamper", "connect": {"sub": [0]}, "dirs": [0], "k": DAMPING},
            "spring": {"type": "LinearSpring", "connect": {"sub": [0]}, "dirs": [0], "k": STIFFNESS},
            "cubic": {"type": "CubicSpring", "connect": {"sub": [0]}, "dirs": [0], "k": CUBIC},
            "force": {"type": "CosinusForcing", "connect": {"sub": [0]}, "dirs": [0], "amp": FORCING},
        },
        "analysis": {"FRF": {"study": "frf", "puls_inf": W0, "puls_sup": W1, "ds0": 0.01, "ds_max": 0.05,
                             "ds_min": 1e-6, "verbose": False, "solver": solver, "solver_options": solver_options}},
    }


def pyharm_worker(repeats):
    """Runs inside benchmarks/.venv-others; prints one JSON line per solver."""
    import logging

    logging.disable(logging.CRITICAL)
    import warnings

    warnings.filterwarnings("ignore")
    from pyHarm.Maestro import Maestro

    for solver, tol in (("NewtonRaphson", TOLERANCE), ("scipyroot", 1e-4)):
        def once():
            a = time.perf_counter()
            maestro = Maestro(pyharm_input(solver, tol))
            maestro.operate()
            return maestro, time.perf_counter() - a

        maestro, first = once()
        times = [once()[1] for _ in range(repeats)]
        sols = [s for s in maestro.nls["FRF"].SolList if s.flag_accepted]
        x = np.array([np.asarray(s.x, dtype=float) for s in sols])
        r = [float(np.max(np.abs(s.R))) if getattr(s, "R", None) is not None else float("nan") for s in sols]
        print(json.dumps({
            "tool": f"pyHarm {_pyharm_version()} ({solver}, tol {tol:g})",
            "points": len(sols), "first_run_s": first, "curve_s": statistics.median(times),
            "hill_s": None, "unstable_points": None,
            "w": x[:, -1].tolist(), "coeffs": x[:, :-1].tolist(), "max_residual": float(np.nanmax(r)),
        }), flush=True)


def _pyharm_version():
    try:
        from importlib.metadata import version

        return version("pyHarm-os")
    except Exception:  # noqa: BLE001
        return "?"


def ensure_others_venv():
    """Create ``benchmarks/.venv-others`` with pyharm-os; returns its python or raises RuntimeError."""
    python = OTHERS_VENV / "bin" / "python"
    if not python.exists():
        subprocess.run(["python3", "-m", "venv", str(OTHERS_VENV)], check=True)
    check = subprocess.run([str(python), "-c", "import pyHarm"], capture_output=True, text=True)
    if check.returncode != 0:
        inst = subprocess.run([str(python), "-m", "pip", "install", "-q", "pyharm-os"], capture_output=True, text=True)
        if inst.returncode != 0:
            raise RuntimeError(f"pip install pyharm-os failed: {inst.stderr.strip().splitlines()[-1:]}")
    return python


def run_pyharm(repeats):
    try:
        python = ensure_others_venv()
    except (RuntimeError, subprocess.CalledProcessError, OSError) as exc:
        return [], f"pyHarm not run: {exc}"
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    proc = subprocess.run([str(python), str(Path(__file__).resolve()), "--pyharm-worker", "--repeats", str(repeats)],
                          capture_output=True, text=True, env=env, cwd=str(HERE))
    rows = [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]
    if proc.returncode != 0 or not rows:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return rows, f"pyHarm failed (exit {proc.returncode}): {tail}"
    return rows, None


# ----------------------------------------------------------------------------- driver
def run(quick=False, repeats=None, nlvib=None):
    """Returns ``(rows, notes)``; each row a dict (see :func:`table`). `nlvib`: a local copy of
    NLvib to run under Octave as well (:mod:`bench_nlvib`)."""
    repeats = repeats or (2 if quick else 5)
    checks = CHECK_W[::2] if quick else CHECK_W
    a = time.perf_counter()
    duffing_ti(checks[0])
    t_ti = time.perf_counter() - a
    rows = [run_hbgear(repeats)]
    others, note = run_pyharm(repeats)
    rows += others
    # hbgear again with its step limit set so that it stores about as many points as pyHarm
    if others:
        target = others[0]["points"]
        ds = 0.05
        for _ in range(6):
            trial = run_hbgear(1, ds_max=ds)
            if abs(trial["points"] - target) <= 0.1 * target:
                break
            ds *= trial["points"] / target
        same = run_hbgear(repeats, ds_max=ds)
        same["tool"] = f"hbgear (ds_max={ds:.3g}, ~pyHarm's point count)"
        rows.append(same)
    if nlvib:
        import bench_nlvib

        row, more = bench_nlvib.run(nlvib, rows[-1]["points"], repeats=min(repeats, 3))
        if row is not None:
            rows.append(row)
        note = "; ".join(filter(None, [note] + more))
    for row in rows:
        row["error_vs_ti"] = branch_error(row["w"], np.asarray(row["coeffs"]), checks)
        row["per_point_ms"] = 1e3 * row["curve_s"] / max(row["points"], 1)
    notes = [f"reference: DOP853 rtol 1e-11 from rest at each tool's point nearest {list(checks)} rad/s "
             f"(outside the bistable band); {t_ti:.2f} s per frequency"]
    if note:
        notes.append(note)
    return rows, notes


def table(rows):
    head = f"{'tool':52s} {'points':>6s} {'first run [s]':>13s} {'curve [s]':>9s} {'per point [ms]':>14s} " \
           f"{'Hill all pts [s]':>16s} {'Hill/pt [ms]':>12s} {'err vs TI':>9s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        hill = "-" if r["hill_s"] is None else f"{r['hill_s']:.3f}"
        hill_pt = "-" if r["hill_s"] is None else f"{1e3 * r['hill_s'] / max(r['points'], 1):.3f}"
        lines.append(f"{r['tool']:52s} {r['points']:6d} {r['first_run_s']:13.2f} {r['curve_s']:9.3f} "
                     f"{r['per_point_ms']:14.2f} {hill:>16s} {hill_pt:>12s} {r['error_vs_ti']:9.1e}")
    base = [r for r in rows if r["tool"].startswith("hbgear (ds_max")] or rows[:1]
    b = base[0]
    with_hill = 1e3 * (b["curve_s"] + b["hill_s"]) / b["points"]
    lines.append(f"Hill per point ({b['tool']}): batched {1e3 * b['hill_s'] / b['points']:.3f} ms, one call per "
                 f"point {1e3 * b['hill_per_point_call_s'] / b['points']:.3f} ms "
                 f"({b['hill_per_point_call_s'] / b['hill_s']:.1f}x; max |difference| of the multipliers "
                 f"{b['hill_batch_vs_single_max_diff']:.1e})")
    for r in rows:
        if not r["tool"].startswith("hbgear"):
            lines.append(f"speed-up per point, hbgear (same point count, curve only) vs {r['tool']}: "
                         f"{r['per_point_ms'] / b['per_point_ms']:.1f}x; with Hill (batched) on every point "
                         f"({with_hill:.2f} ms): {r['per_point_ms'] / with_hill:.1f}x")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--pyharm-worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.pyharm_worker:
        pyharm_worker(args.repeats or 3)
        return 0
    rows, notes = run(args.quick, args.repeats)
    print(table(rows))
    for n in notes:
        print("note:", n)
    return 0


if __name__ == "__main__":
    sys.exit(main())
