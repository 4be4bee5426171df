r"""The whole ``hbgear`` commands against their references, measured in one run (issue "Speed, round two").

Each row is a ratio against a reference measured in the same run, in alternated pairs, the
median of the pairs reported:

1. ``hbgear frc examples/paper_table1.toml --set friction.model=NLTV --set friction.law=arctan
   --set sweep.speed_rpm_start=3000`` (2406 points; warm disk cache, after one untimed run):
   wall time of the whole process per point against an independent time integration to steady
   state of the same model at the same speeds, :func:`hbgear.gear.simulate.simulate` with
   DOP853 (piecewise between the mesh breakpoints, ``rtol`` 1e-6, steady to 1e-4), at speeds
   of the curve spread over its range (goal: >= 1000x). From the command's ``frc.json``: its
   stages, and the stability of every point against the continuation (goal: <= 1x; the issue
   named Hill's method, which the command used until the variational equations were compiled).
   Accuracy next to it: the DTE waveform of harmonic balance (``H = 32``, ``N = 1024``) against
   the integration at those speeds (RMS of the difference over one steady mesh period / RMS of
   the DTE fluctuation), the command's multipliers and Hill's against SciPy's DOP853 on the
   variational equations there, the period doublings the command located.
2. ``hbgear frc examples/paper_table1.toml`` (LTV, 2060 points): wall time against
   ``python -c "import jax"`` (goal <= 2x with a warm cache; <= 5x on a first run with an
   empty disk cache, each cold run with a cache of its own). Accuracy: the largest scaled
   residual of ``frc.csv`` against the tolerance.
3. ``hbgear --help`` against ``python -c "import jax"`` (goal <= 0.3x).

Run: ``python benchmarks/bench_commands.py [--quick]``.
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "paper_table1.toml"
NLTV = ["--set", "friction.model=NLTV", "--set", "friction.law=arctan", "--set", "sweep.speed_rpm_start=3000"]
TI_SETTINGS = {"method": "DOP853", "rtol": 1e-6, "steady_tolerance": 1e-4}


def _env(cache_dir=None) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))  # this checkout's hbgear
    if cache_dir is not None:
        env["HBGEAR_CACHE_DIR"] = str(cache_dir)
    return env


def _wall(args, env) -> float:
    """Wall time [s] of ``python args`` in a fresh process (output discarded; failure raises)."""
    t = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, cwd=ROOT, check=True, capture_output=True)
    return time.perf_counter() - t


def _frc(out: Path, extra, env) -> tuple[float, dict]:
    wall = _wall(["-m", "hbgear", "frc", str(CONFIG), "--no-progress", "--out", str(out), *extra], env)
    return wall, json.loads((out / "frc.json").read_text())


def _import_jax(env) -> float:
    return _wall(["-c", "import jax"], env)


def _ml_dtypes_import(env) -> tuple[str, float]:
    """The installed ``ml_dtypes`` (JAX's dtypes) and the seconds its import takes after numpy's:
    0.7.0 took 0.7 s of a 1.3 s ``import jax`` on this project's machine (pyproject excludes it)."""
    code = ("import time, numpy; t = time.perf_counter(); import ml_dtypes; "
            "print(ml_dtypes.__version__, time.perf_counter() - t)")
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=ROOT, check=True, capture_output=True, text=True)
    version, seconds = out.stdout.split()
    return version, float(seconds)


def _ti_points(model, speeds_rpm):
    """Per speed: wall time [s] of the integration to steady state and its response."""
    from hbgear.gear.simulate import simulate
    from hbgear.gear.solve import rpm_to_rad_s

    try:  # warm-up (JIT of the right-hand side); a short run never reaches steady state
        simulate(model, rpm_to_rad_s(float(speeds_rpm[0])), max_cycles=2, **TI_SETTINGS)
    except Exception:  # noqa: BLE001
        pass
    out = []
    for rpm in speeds_rpm:
        t = time.perf_counter()
        response = simulate(model, rpm_to_rad_s(float(rpm)), **TI_SETTINGS)
        out.append((time.perf_counter() - t, response))
    return out


def _accuracy(model, speeds_rpm, responses) -> dict:
    """DTE of harmonic balance vs the integrations; the multipliers of the command's route (the
    compiled variational equations at the branch's tolerance) and Hill's, each against SciPy's
    DOP853 on the variational equations (rtol 1e-10), at the same HB solutions."""
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.monodromy import drop_trivial, monodromy_variational, state_synthesis
    from hbgear.engine.stability import VARIATIONAL_ATOL, VARIATIONAL_RTOL
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem

    from bench_duffing_tools import max_pair_distance

    system = GearSystem(model)
    hb = HarmonicBalance(model.ndof, 32, 1, 1024)
    dte, hill, route = [], [], []
    sols = []
    for rpm, response in zip(speeds_rpm, responses):
        w = rpm_to_rad_s(float(rpm))
        sol = solve_periodic(model, w, harmonics=32, samples=1024)
        sols.append(sol)
        s, q = response.s, response.q[0]
        q_hb, _ = sol.state_at(s % 1.0)
        q_hb = q_hb[0]
        fluct = q - q.mean()
        dte.append(float(np.sqrt(np.mean((q_hb - q) ** 2)) / np.sqrt(np.mean(fluct**2))))
    omegas = rpm_to_rad_s(np.asarray(speeds_rpm, dtype=float))
    state = state_synthesis(np.stack([s.coefficients for s in sols]), 32, np.array([s.base_frequency for s in sols]))
    reference = monodromy_variational(system, omegas, state, integrator="DOP853")
    compiled = monodromy_variational(system, omegas, state, rtol=VARIATIONAL_RTOL, atol=VARIATIONAL_ATOL,
                                     integrator="compiled")
    for phi, phi_route, sol, w in zip(reference, compiled, sols, omegas):
        exact = drop_trivial(np.linalg.eigvals(phi), system)
        route.append(max_pair_distance(drop_trivial(np.linalg.eigvals(phi_route), system), exact))
        mult = hill_multipliers(hb, sol.z, float(w), system)
        hill.append(max_pair_distance(mult, exact) if len(mult) == len(exact) else float("nan"))
    return {"dte_rel_rms_max": max(dte), "route_vs_dop853_max": float(np.max(route)),
            "hill_vs_variational_max": float(np.nanmax(hill))}


def nltv_command(quick=False) -> dict:
    """Row 1 (see the module docstring)."""
    from hbgear.build import build_model
    from hbgear.config import load_config

    model = build_model(load_config(CONFIG, ["friction.model=NLTV", "friction.law=arctan"]))
    samples = 2 if quick else 4
    pairs = 1 if quick else 2
    env = _env()
    with tempfile.TemporaryDirectory(prefix="hbgear-bench-frc-") as tmp:
        out = Path(tmp)
        _frc(out, NLTV, env)  # compiles into (or loads from) the disk cache: the timed runs are warm
        rows = np.loadtxt(out / "frc.csv", delimiter=",", skiprows=1)
        speeds = rows[:, 0][rows[:, 8] == 1]
        picks = np.linspace(speeds.min(), speeds.max(), samples + 2)[1:-1]
        picks = [float(speeds[np.argmin(np.abs(speeds - x))]) for x in picks]
        commands, ti = [], []
        for _ in range(pairs):  # alternated: the command, then the integrations
            commands.append(_frc(out, NLTV, env))
            ti += _ti_points(model, picks)
        record = commands[-1][1]
    points = int(record["points"])
    wall = statistics.median(w for w, _ in commands)
    ti_per_point = statistics.median(t for t, _ in ti)
    stages = {k: statistics.median(r["timings_s"][k] for _, r in commands)
              for k in ("compile_and_start_point", "continuation", "stability", "period_doubling", "outputs", "total")}
    accuracy = _accuracy(model, picks, [r for _, r in ti[-samples:]])
    return {
        "points": points, "wall_s": wall, "wall_all_s": [w for w, _ in commands], "per_point_ms": 1e3 * wall / points,
        "ti_per_point_s": ti_per_point, "ti_all_s": [t for t, _ in ti], "ti_speeds_rpm": picks,
        "speedup_per_point": ti_per_point / (wall / points), "stages_s": stages,
        "stability_over_continuation": stages["stability"] / stages["continuation"],
        "stability_method": record["stability"]["method"],
        "period_doublings_rpm": [p.get("speed_rpm") for p in record["period_doubling"]], **accuracy,
    }


def ltv_command(quick=False) -> dict:
    """Row 2: warm pairs with ``import jax``, then cold runs (each with an empty cache of its own)."""
    pairs, cold_runs = (2, 1) if quick else (3, 2)
    env = _env()
    warm, jax_times, cold, cold_jax = [], [], [], []
    with tempfile.TemporaryDirectory(prefix="hbgear-bench-ltv-") as tmp:
        out = Path(tmp)
        _frc(out, [], env)
        for _ in range(pairs):
            warm.append(_frc(out, [], env)[0])
            jax_times.append(_import_jax(env))
        record = json.loads((out / "frc.json").read_text())
        for _ in range(cold_runs):
            cache = Path(tempfile.mkdtemp(prefix="hbgear-bench-cold-"))
            try:
                cold.append(_frc(out, [], _env(cache))[0])
                cold_jax.append(_import_jax(env))
            finally:
                shutil.rmtree(cache, ignore_errors=True)
    return {
        "points": int(record["points"]), "wall_s": statistics.median(warm), "import_jax_s": statistics.median(jax_times),
        "ratio": statistics.median(w / j for w, j in zip(warm, jax_times)), "ratios": [w / j for w, j in zip(warm, jax_times)],
        "cold_s": statistics.median(cold), "cold_ratio": statistics.median(c / j for c, j in zip(cold, cold_jax)),
        "cold_ratios": [c / j for c, j in zip(cold, cold_jax)], "max_residual": record["max_residual"],
        "tolerance": record["tolerance"], "stages_s": record["timings_s"], "ml_dtypes": _ml_dtypes_import(env),
    }


def help_command(quick=False) -> dict:
    """Row 3: ``hbgear --help`` and ``import jax``, alternated."""
    env = _env()
    pairs = 3 if quick else 5
    helps, jaxes = [], []
    for _ in range(pairs):
        helps.append(_wall(["-m", "hbgear", "--help"], env))
        jaxes.append(_import_jax(env))
    return {"wall_s": statistics.median(helps), "import_jax_s": statistics.median(jaxes),
            "ratio": statistics.median(h / j for h, j in zip(helps, jaxes))}


def run(quick=False) -> dict:
    return {"nltv": nltv_command(quick), "ltv": ltv_command(quick), "help": help_command(quick)}


def table(res) -> str:
    n, lt, hp = res["nltv"], res["ltv"], res["help"]
    st = n["stages_s"]
    lines = [
        f"NLTV frc, {n['points']} points: whole command {n['wall_s']:.2f} s ({n['per_point_ms']:.2f} ms a point; runs "
        + ", ".join(f"{w:.2f}" for w in n["wall_all_s"]) + " s)",
        f"  stages (median): compile+start {st['compile_and_start_point']:.2f}, continuation {st['continuation']:.2f}, "
        f"stability {st['stability']:.2f}, period doubling {st['period_doubling']:.2f}, csv+json {st['outputs']:.2f} s "
        f"(in-process total {st['total']:.2f} s)",
        f"  stability: {n['stability_method']}",
        f"  time integration (DOP853 rtol 1e-6, steady 1e-4) per point: {n['ti_per_point_s']:.2f} s (median of "
        f"{len(n['ti_all_s'])} at {', '.join(f'{x:.0f}' for x in n['ti_speeds_rpm'])} rpm)",
        f"  speed-up per point, whole command vs TI: {n['speedup_per_point']:.0f}x; stability on every point / "
        f"continuation: {n['stability_over_continuation']:.2f}",
        f"  accuracy: HB vs TI DTE {100 * n['dte_rel_rms_max']:.3f} % (max); multipliers (max |d|) against DOP853 on "
        f"the variational equations: the command's route {n['route_vs_dop853_max']:.1e}, Hill (H = 32) "
        f"{n['hill_vs_variational_max']:.1e}; period doublings at "
        + ", ".join(f"{x:.6g}" for x in n["period_doublings_rpm"] if x is not None) + " rpm",
        f"LTV frc, {lt['points']} points: {lt['wall_s']:.2f} s warm, import jax {lt['import_jax_s']:.2f} s: "
        f"{lt['ratio']:.2f}x (pairs " + ", ".join(f"{r:.2f}" for r in lt["ratios"]) + f"); first run, empty cache "
        f"{lt['cold_s']:.2f} s: {lt['cold_ratio']:.2f}x; max residual {lt['max_residual']:.1e} (tolerance "
        f"{lt['tolerance']:.0e}); of import jax, ml_dtypes {lt['ml_dtypes'][0]} {lt['ml_dtypes'][1]:.2f} s",
        f"hbgear --help {hp['wall_s']:.3f} s, import jax {hp['import_jax_s']:.2f} s: {hp['ratio']:.2f}x",
    ]
    return "\n".join(lines)


def main(argv=None):
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    res = run(args.quick)
    print(table(res))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
