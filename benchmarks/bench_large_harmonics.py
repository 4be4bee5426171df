r"""Many harmonics: the structured Newton path (FFT products, GMRES with the mean-Jacobian
preconditioner) against the dense one (Jacobian matrix, LU), and the H = 2048 solve.

Problem: the reference pair (``examples/paper_table1.toml``), ``friction.model = NLTV``,
``law = arctan``, soft spring, 200 rpm, ``N = 4H + 8`` AFT samples.

Part 1 -- **the command** ``hbgear solve examples/paper_table1.toml --speed 200 --set
friction.model=NLTV --set friction.law=arctan --set solver.harmonics=2048 --set
solver.time_samples=8200``, in a fresh process, twice: the first compiles into the disk cache
(``HBGEAR_CACHE_DIR``: empty when run from ``run.py``), the second loads from it. Wall time of
the whole process and its peak resident memory (``VmHWM`` of the child at its exit); DTE RMS and ``max_abs_floquet`` from its ``solution.json``.

Part 2 -- **one Newton step vs H**, ``H = 64 .. 2048``, dense (up to ``--dense-max``, default
1024: at 2048 its matrices and rule kernel need ~8 GB) and structured (forced with
``operator=...`` on either side of the size rule). Each case: one solve from the quasi-static
state to compile, then three timed solves (one when the first took over 10 s); a step is the
time between two successive linearisations (linearise, linear solve, line search), the median
over the timed steps is reported with the
GMRES products per step, the bytes of the prepared operator and Jacobian, the residual reached
and the DTE RMS. Part 2 runs with the settings of the ``hbgear`` command
(:func:`hbgear.runtime.configure`: one XLA thread when JAX has not run yet in the process, the disk
cache) and with one BLAS thread (``--blas-threads``): on this shared 2-core
machine under load, OpenBLAS's two threads made one LU of 258-1026 unknowns 20-500x slower
than one thread (0.36 vs 188 ms at 258, load average ~7), which would measure the machine's
load instead of the methods. The slope of log(step time) vs log(H) is fitted over all structured sizes and
over H >= 256.

Part 3 -- **accuracy**: dense vs structured at each H where both ran (the DTE coefficients and
the DTE RMS), and the convergence of the structured DTE RMS in H: the differences between
successive H, their ratio, and the H = 2048 difference the previous ratio predicts.

Run: ``python benchmarks/bench_large_harmonics.py [--quick] [--dense-max H]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # measure this checkout, not an installed hbgear
CONFIG = ROOT / "examples" / "paper_table1.toml"
OVERRIDES = ["friction.model=NLTV", "friction.law=arctan"]
SPEED_RPM, TOL = 200.0, 1e-9
HARMONICS = (64, 128, 256, 512, 1024, 2048)
REPEATS = 3  # timed solves per case (1 when the compiling one took over 10 s)

# the child of part 1: run the CLI, then report its own peak memory on the last line of stderr:
# VmHWM of /proc/self/status (this process image's peak; getrusage's ru_maxrss survives exec and
# so reports a large parent's size instead, e.g. under run.py)
_CHILD = """
import json, resource, sys
from hbgear.cli import main
code = main(sys.argv[1:])
try:
    peak = next(int(line.split()[1]) for line in open("/proc/self/status") if line.startswith("VmHWM:"))
except (OSError, StopIteration):
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"maxrss_kb": peak}), file=sys.stderr)
sys.exit(code)
"""


def command(harmonics: int = 2048, samples: int = 8200) -> list[str]:
    sets = [*OVERRIDES, f"solver.harmonics={harmonics}", f"solver.time_samples={samples}"]
    return ["solve", str(CONFIG), "--speed", f"{SPEED_RPM:g}"] + [a for s in sets for a in ("--set", s)]


def run_command(out_dir: Path) -> dict:
    """Part 1, one run: wall time, peak RSS and the solution's numbers."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", _CHILD, *command(), "--out", str(out_dir)], env=env,
                          capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        raise RuntimeError(f"hbgear solve failed ({done.returncode}): {done.stderr[-2000:]}")
    rss = json.loads(done.stderr.strip().splitlines()[-1])["maxrss_kb"] / 1024.0
    record = json.loads((out_dir / "solution.json").read_text())
    return {"wall_s": wall, "rss_mb": rss, "dte_rms_um": record["dte_rms_um"],
            "max_abs_floquet": record["max_abs_floquet"], "newton": record["newton_iterations"],
            "residual": record["residual"], "line": done.stdout.strip()}


def _problem():
    from hbgear.build import build_model
    from hbgear.config import load_config
    from hbgear.gear.solve import rpm_to_rad_s
    from hbgear.gear.system import GearSystem

    model = build_model(load_config(CONFIG, [f"{o.split('=')[0]}='{o.split('=')[1]}'" for o in OVERRIDES]))
    return model, GearSystem(model), rpm_to_rad_s(SPEED_RPM)


def _bytes(tree) -> int:
    import jax

    return sum(int(np.asarray(leaf).nbytes) for leaf in jax.tree_util.tree_leaves(tree))


def newton_case(harmonics: int, operator: str) -> dict:
    """Part 2, one case: a compiling solve, then a timed one with a stamp at every linearisation."""
    import jax.numpy as jnp

    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.newton import newton
    from hbgear.gear.solve import PeriodicSolution, _quasi_static_start

    model, system, omega = _problem()
    hb = HarmonicBalance(model.ndof, harmonics, 1, 4 * harmonics + 8, operator=operator)
    prepared = hb.prepare(system)
    stamps, pieces = [], {}

    def both(z):
        stamps.append(time.perf_counter())
        r, jac = hb.residual_and_linearization(jnp.asarray(z), omega, system, prepared)
        pieces["jacobian"] = getattr(jac, "linearization", jac)
        return r, jac

    def resid(z):
        return hb.residual(jnp.asarray(z), omega, system, prepared)

    z0 = _quasi_static_start(model, hb, system)
    start = time.perf_counter()
    newton(both, resid, z0, tolerance=TOL)  # compiles
    repeats = REPEATS if time.perf_counter() - start < 10.0 else 1
    steps, totals = [], []
    for _ in range(repeats):
        stamps.clear()
        start = time.perf_counter()
        result = newton(both, resid, z0, tolerance=TOL)
        totals.append(time.perf_counter() - start)
        steps += list(np.diff(stamps))
        if not result.converged:
            raise RuntimeError(f"H = {harmonics} {operator}: Newton did not converge ({result.residual_norm:.2e})")
    total = statistics.median(totals)
    solution = PeriodicSolution.from_z(model, omega, result.z, hb, residual_norm=result.residual_norm)
    return {"H": harmonics, "operator": operator, "size": hb.size, "step_s": float(np.median(steps)),
            "steps": result.iterations, "solve_s": total, "repeats": repeats, "products": result.linear_iterations / max(1, result.iterations),
            "memory_mb": (_bytes(prepared) + _bytes(pieces["jacobian"])) / 2**20, "residual": result.residual_norm,
            "dte_rms_um": solution.summary()["dte_rms_um"], "dte": solution.coefficients[0]}


def slope(rows, low: int = 0) -> float:
    chosen = [r for r in rows if r["H"] >= low]
    return float(np.polyfit(np.log([r["H"] for r in chosen]), np.log([r["step_s"] for r in chosen]), 1)[0])


def run(quick: bool = False, dense_max: int | None = None, command_runs: int = 2, harmonics_list=HARMONICS,
        blas_threads: int | None = 1) -> dict:
    dense_max = dense_max or (512 if quick else 1024)
    from hbgear import runtime

    # part 2 in this process with the settings the hbgear command runs with (one XLA thread: only
    # if JAX has not run yet in this process, e.g. not under run.py; the disk cache)
    out = {"command": [], "cases": [], "runtime": runtime.configure()}
    with tempfile.TemporaryDirectory(prefix="hbgear-large-h-") as tmp:
        for k in range(command_runs):
            out["command"].append(run_command(Path(tmp) / f"run{k}"))
            print(f"  command run {k + 1}: {out['command'][-1]['wall_s']:.1f} s, "
                  f"{out['command'][-1]['rss_mb']:.0f} MB peak", flush=True)
    import scipy.linalg  # noqa: F401  (loaded before the limit below: it has its own BLAS)
    from threadpoolctl import threadpool_limits

    out["blas_threads"] = blas_threads
    with threadpool_limits(blas_threads):
        for harmonics in harmonics_list:
            for operator in ("dense", "structured"):
                if operator == "dense" and harmonics > dense_max:
                    continue
                case = newton_case(harmonics, operator)
                out["cases"].append(case)
                print(f"  H = {harmonics:4d} {operator:10s} step {1e3 * case['step_s']:8.1f} ms", flush=True)
    return out


def table(out: dict) -> str:
    lines = ["part 1: the H = 2048 command (whole process)",
             f"{'run':>4s} {'wall':>8s} {'peak RSS':>10s} {'DTE rms um':>16s} {'max|Floquet|':>14s} {'Newton':>7s}"]
    for k, c in enumerate(out["command"], start=1):
        lines.append(f"{k:4d} {c['wall_s']:7.2f}s {c['rss_mb']:8.0f}MB {c['dte_rms_um']:16.10f} "
                     f"{c['max_abs_floquet']:14.10f} {c['newton']:7d}")
    lines.append("  (run 1 compiles into the disk cache, run 2 loads from it)")
    lines += ["", "part 2: one Newton step vs H (median over the steps of up to 3 timed solves after a compiling one; "
              f"BLAS threads: {out.get('blas_threads') or 'default'}; one XLA thread: "
              f"{out.get('runtime', {}).get('single_thread')})",
              f"{'H':>5s} {'size':>6s} {'path':>10s} {'step ms':>9s} {'steps':>5s} {'GMRES/step':>10s} "
              f"{'operator MB':>11s} {'residual':>9s} {'DTE rms um':>15s}"]
    for c in out["cases"]:
        products = f"{c['products']:10.0f}" if c["operator"] == "structured" else f"{'LU':>10s}"
        lines.append(f"{c['H']:5d} {c['size']:6d} {c['operator']:>10s} {1e3 * c['step_s']:9.1f} {c['steps']:5d} "
                     f"{products} {c['memory_mb']:11.1f} {c['residual']:9.1e} {c['dte_rms_um']:15.10f}")
    structured = [c for c in out["cases"] if c["operator"] == "structured"]
    dense = [c for c in out["cases"] if c["operator"] == "dense"]
    def slopes(cases):  # over all H and over H >= 256, where there are two sizes to fit
        if len(cases) < 2:
            return "(fewer than two sizes)"
        large = slope(cases, 256) if len([c for c in cases if c["H"] >= 256]) > 1 else float("nan")
        return f"{slope(cases):.2f} (H = {cases[0]['H']} .. {cases[-1]['H']}), {large:.2f} (H >= 256)"

    lines.append(f"log-log slope of the structured step: {slopes(structured)}; dense: {slopes(dense)}")
    lines += ["", "part 3: accuracy",
              f"{'H':>5s} {'|DTE coeff s - d| / max':>24s} {'DTE rms s - d [um]':>19s}"]
    by_h = {c["H"]: c for c in structured}
    for d in dense:
        s = by_h[d["H"]]
        lines.append(f"{d['H']:5d} {np.max(np.abs(s['dte'] - d['dte'])) / np.max(np.abs(d['dte'])):24.1e} "
                     f"{s['dte_rms_um'] - d['dte_rms_um']:19.1e}")
    lines.append(f"{'H':>5s} {'DTE rms (structured) um':>24s} {'d = change from H/2':>20s} {'ratio':>6s} "
                 f"{'d predicted':>12s}")
    rms = [c["dte_rms_um"] for c in structured]
    diffs = [None] + [b - a for a, b in zip(rms, rms[1:])]
    ratios = [None, None] + [a / b for a, b in zip(diffs[1:], diffs[2:])]
    for i, c in enumerate(structured):
        # the previous ratio carried on, once the changes shrink monotonically
        predicted = diffs[i - 1] / ratios[i - 1] if i >= 3 and ratios[i - 1] > 1 else None
        lines.append(f"{c['H']:5d} {c['dte_rms_um']:24.12f} {_num(diffs[i], 20, '.3e')} {_num(ratios[i], 6, '.2f')} "
                     f"{_num(predicted, 12, '.3e')}")
    return "\n".join(lines)


def _num(value, width: int, spec: str) -> str:
    return " " * width if value is None else f"{value:{width}{spec}}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="dense up to H = 512")
    parser.add_argument("--dense-max", type=int, default=None, help="largest H for the dense path")
    parser.add_argument("--harmonics", type=int, nargs="+", default=list(HARMONICS), help="the H of part 2")
    parser.add_argument("--command-runs", type=int, default=2, help="runs of the H = 2048 command (part 1)")
    parser.add_argument("--blas-threads", type=int, default=1,
                        help="BLAS threads in part 2 (0: the libraries' default)")
    args = parser.parse_args(argv)
    print(table(run(args.quick, args.dense_max, args.command_runs, tuple(args.harmonics), args.blas_threads or None)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
