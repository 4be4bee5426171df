r"""Studies: samples per minute of ``hbgear study`` in local worker processes against one process,
and the share of the time spent compiling.

The study: 64 Monte Carlo samples (16 with ``--quick``) of the reference pair
(``examples/paper_table1.toml``) with ``mesh.damping_ratio`` uniform in [0.01, 0.04] and
``load.torque_pinion_Nm`` uniform in [150, 300] N m, each a full curve with its Floquet
stability on a small problem (constant torques, LTV, H = 8, 64 samples, 12000 -> 14000 rpm:
140-250 points). Each run is the whole command, ``python -m hbgear study CONFIG --workers N``,
in a fresh process (start-up, imports and compilation included), timed from outside. One
warm-up study of 2 samples first fills the disk compilation cache (its time is reported on its
own line); then, alternating, ``--workers 1`` (in the command's own process) and ``--workers P``
(P = the CPUs: spawned worker processes), ``repeats`` times each; medians and their ratio.
The CPU time of each command (with its worker processes) says what the workers cost beyond the
samples themselves, whatever else the machine runs. The compile share is ``study.json``'s
``compile_fraction``: the time inside JAX's compile events (tracing, lowering, XLA compilation or
a disk-cache load) over the samples' own time.

Run: ``python benchmarks/bench_study.py [--quick] [--repeats N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "examples" / "paper_table1.toml"
FAST = ['boundary.output="torques"', "solver.harmonics=8", "solver.time_samples=64", "sweep.speed_rpm_start=12000.0",
        "sweep.speed_rpm_stop=14000.0"]


def study_config(folder: Path, samples: int) -> Path:
    """The benchmark's study file: the reference pair with a [study] table (FAST comes as --set)."""
    path = folder / f"bench_study_{samples}.toml"
    path.write_text(CONFIG.read_text() + f"""
[study]
kind = "monte_carlo"
samples = {samples}
seed = 1
[study.parameters]
"mesh.damping_ratio" = {{ uniform = [0.01, 0.04] }}
"load.torque_pinion_Nm" = {{ uniform = [150.0, 300.0] }}
""")
    return path


def one_run(config: Path, out: Path, workers: int) -> dict:
    """``hbgear study`` in a fresh process: wall time from outside and study.json's timings."""
    argv = [sys.executable, "-m", "hbgear", "study", str(config), "--out", str(out), "--workers", str(workers),
            "--no-progress", "--fresh"]
    for s in FAST:
        argv += ["--set", s]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    done = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)  # the command and its worker processes
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f"hbgear study failed ({done.returncode}): {done.stderr.strip()}")
    summary = json.loads((out / "study.json").read_text())
    t_s = summary["timings_s"]
    return {"wall": wall, "cpu": cpu, "inside": t_s["wall"], "compile_fraction": t_s["compile_fraction"],
            "compile_s": t_s["compile_seconds"], "sample_s": t_s["sample_seconds"], "samples": summary["samples"],
            "succeeded": summary["succeeded"], "mode": summary["execution"]["mode"],
            "workers": summary["execution"]["workers"]}


def run(quick=False, repeats=None):
    from hbgear.tasks import available_workers

    repeats = repeats or (1 if quick else 3)
    n = 16 if quick else 64
    cpus = available_workers()
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="hbgear-bench-study-") as tmp:
        tmp = Path(tmp)
        warm = one_run(study_config(tmp, 2), tmp / "warm", 1)
        config = study_config(tmp, n)
        runs = {1: [], cpus: []}
        for _ in range(repeats):
            for w in runs:
                runs[w].append(one_run(config, tmp / f"w{w}", w))
    result = {"samples": n, "cpus": cpus, "repeats": repeats, "warm_up": warm, "load_before": load,
              "load_after": os.getloadavg()[0]}
    for w, rs in runs.items():
        wall = statistics.median(r["wall"] for r in rs)
        result[w] = {"wall_s": wall, "walls": [r["wall"] for r in rs], "per_minute": 60.0 * n / wall,
                     "cpu_s": statistics.median(r["cpu"] for r in rs),
                     "compile_fraction": statistics.median(r["compile_fraction"] for r in rs),
                     "compile_s": statistics.median(r["compile_s"] for r in rs),
                     "sample_s": statistics.median(r["sample_s"] for r in rs), "mode": rs[0]["mode"],
                     "workers": rs[0]["workers"], "succeeded": min(r["succeeded"] for r in rs)}
    result["speedup"] = result[cpus]["per_minute"] / result[1]["per_minute"]
    return result


def table(r) -> str:
    cpus = r["cpus"]
    lines = [f"{r['samples']}-sample Monte Carlo study (curves of 140-250 points), whole command in a fresh process, "
             f"median of {r['repeats']}; load average {r['load_before']:.1f} before, {r['load_after']:.1f} after",
             f"warm-up study (2 samples, one process): {r['warm_up']['wall']:.1f} s, "
             f"{100 * r['warm_up']['compile_fraction']:.0f}% of its sample time compiling"]
    for w in (1, cpus):
        x = r[w]
        lines.append(f"--workers {w} ({x['mode']}, {x['workers']} worker(s)): {x['wall_s']:.1f} s "
                     f"({', '.join(f'{v:.1f}' for v in x['walls'])}), {x['per_minute']:.0f} samples/min, "
                     f"compiling {100 * x['compile_fraction']:.0f}% of the samples' time "
                     f"({x['compile_s']:.1f} of {x['sample_s']:.1f} s), CPU {x['cpu_s']:.1f} s (command and its "
                     f"workers), {x['succeeded']} of {r['samples']} succeeded")
    lines.append(f"local processes / one process: {r['speedup']:.2f}x samples per minute on {cpus} CPUs; "
                 f"CPU time {r[cpus]['cpu_s'] / r[1]['cpu_s']:.2f}x")
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
