"""Run all hbgear benchmarks in one process on this machine and print one table of results.

``python benchmarks/run.py [--quick] [--cache-dir DIR] [--nlvib DIR]`` (``--quick``: smaller
ranges, fewer repeats, a few minutes; the compilation cache is a new empty directory unless
``--cache-dir`` names one, so the first curve's overhead is measured cold; ``--nlvib``: a local
copy of NLvib, whose Duffing curve then runs under GNU Octave in section 2). Each benchmark prints its own details first; the summary table at the
end sets each measured number next to its goal from the issue. The machine (``nproc``, CPU
model, load average) and the versions are printed with it: compare numbers from one run only.
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's hbgear


def machine():
    cpu = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import jax
    import numpy
    import scipy

    load = os.getloadavg() if hasattr(os, "getloadavg") else ("?",)
    return (f"nproc {os.cpu_count()}, CPU {cpu}, load average {load[0]:.1f}; Python {platform.python_version()}, "
            f"jax {jax.__version__}, numpy {numpy.__version__}, scipy {scipy.__version__}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--cache-dir", default=None,
                        help="compilation cache to use (default: a new empty one, so the first curve is cold)")
    parser.add_argument("--nlvib", default=None, metavar="DIR",
                        help="a local copy of NLvib: its Duffing curve under GNU Octave joins section 2 (installs "
                             "Debian's octave with apt-get if missing)")
    args = parser.parse_args(argv)
    # before hbgear is imported: it reads HBGEAR_CACHE_DIR once
    own_cache = None if args.cache_dir else tempfile.mkdtemp(prefix="hbgear-bench-cache-")
    os.environ["HBGEAR_CACHE_DIR"] = args.cache_dir or own_cache
    os.environ.pop("HBGEAR_NO_CACHE", None)
    try:
        return _run(args.quick, args.nlvib)
    finally:
        if own_cache:
            shutil.rmtree(own_cache, ignore_errors=True)


def _run(q, nlvib=None):
    import bench_bearings
    import bench_commands
    import bench_duffing_tools
    import bench_frc_vs_ti
    import bench_large_harmonics
    import bench_newton_breakdown
    import bench_stability_map
    import bench_study

    t0 = time.perf_counter()
    print("#", machine(), flush=True)
    print("# compilation cache:", os.environ["HBGEAR_CACHE_DIR"], flush=True)
    print("\n## 1. frequency-response curve, HB continuation vs time integration", flush=True)
    frc = bench_frc_vs_ti.run(q)  # first: its compile time must be cold
    print(bench_frc_vs_ti.table(frc), flush=True)
    print("\n## 2. Duffing, hbgear vs other Python HB tools", flush=True)
    duff_rows, notes = bench_duffing_tools.run(q, nlvib=nlvib)
    print(bench_duffing_tools.table(duff_rows))
    for n in notes:
        print("note:", n)
    print("\n## 3. stability maps", flush=True)
    smap = bench_stability_map.run(q)
    print(bench_stability_map.table(smap), flush=True)
    print("\n## 4. where the time of a continuation step goes", flush=True)
    b, protos = bench_newton_breakdown.run(q)
    print(bench_newton_breakdown.table(b, protos), flush=True)
    print("\n## 5. studies: local processes vs one process", flush=True)
    study = bench_study.run(q)
    print(bench_study.table(study), flush=True)
    print("\n## 7. many harmonics: the H = 2048 solve, Newton step vs H", flush=True)
    large = bench_large_harmonics.run(q)
    print(bench_large_harmonics.table(large), flush=True)
    print("\n## 8. bearings and shafts: 6 and 8 DOF against the 2-DOF cost (H = 32)", flush=True)
    bear = bench_bearings.run(q)
    print(bench_bearings.table(bear), flush=True)

    print("\n## 6. the whole commands against same-run references (the speed table)", flush=True)
    commands = bench_commands.run(q)
    print(bench_commands.table(commands), flush=True)

    t = b["timer"]
    pts = b["points"]
    floor_ms = b["steps"] * b["lu_ms"] / pts
    hb_rows = [r for r in duff_rows if r["tool"].startswith("hbgear (ds_max")] or duff_rows[:1]
    hbd = hb_rows[0]
    others = [r for r in duff_rows if not r["tool"].startswith("hbgear")]
    best_other = min(others, key=lambda r: r["per_point_ms"]) if others else None
    rows = [
        ("1", "HB per point", f"{1e3 * frc['hb_per_point_s']:.2f} ms", ""),
    ]
    for ti in frc["ti"]:
        rows += [
            ("1", f"HB vs TI rtol {ti['rtol']:.0e} per point (after compile)", f"{ti['speedup_per_point']:.0f}x",
             ">= 1000x"),
            ("1", f"HB vs TI rtol {ti['rtol']:.0e}, max DTE waveform difference", f"{100 * ti['max_error']:.3f} %",
             "<= 0.5 %"),
        ]
    rows += [
        ("1", f"first-curve overhead, empty disk cache (compile + start; median of {len(frc['first_all_s'])})",
         f"{frc['first_s']:.1f} s", "<= 5 s"),
        ("1", "first-curve overhead, another gear pair (fresh process)", f"{frc['new_pair']['first_s']:.1f} s",
         "<= 5 s"),
        ("1", "points on the curve", f"{frc['points']}", ">= 400"),
        ("2", "hbgear per point (curve only)", f"{hbd['per_point_ms']:.2f} ms", ""),
        ("2", "hbgear per point with Hill on every point",
         f"{1e3 * (hbd['curve_s'] + hbd['hill_s']) / hbd['points']:.2f} ms", ""),
    ]
    if best_other is not None:
        rows.append(("2", f"fastest other: {best_other['tool']}", f"{best_other['per_point_ms']:.2f} ms", ""))
        rows.append(("2", "speed-up hbgear (with Hill) vs fastest other",
                     f"{best_other['per_point_ms'] / (1e3 * (hbd['curve_s'] + hbd['hill_s']) / hbd['points']):.1f}x",
                     ">= 15x"))
    else:
        rows.append(("2", "other tools", "not run (see note)", ""))
    rows += [
        ("3", "LTV-A map 100 x 50, after compilation", f"{smap['ltv_map_s']:.3f} s", "<= 2 s"),
        ("3", "NLTV Hill map, per point (HB + Hill)", f"{1e3 * smap['nltv_per_point_s']:.0f} ms", ""),
        ("4", "per point total / LU floor (Python corrector)", f"{b['wall'] / (floor_ms * pts / 1e3):.0f}x", "<= 3x"),
    ]
    for label, c in b["compiled"].items():
        rows.append(("4", f"per point / LU floor ({label}; median of {len(c['floor_ratios'])} paired runs)",
                     f"{c['floor_ratio']:.1f}x", "<= 3x"))
    rows += [
        ("4", "share in (R, J, dR/dp) + R evaluations",
         f"{100 * (t.total.get('eval (R,J,dR/dp)', 0) + t.total.get('eval R (line search)', 0)) / b['wall']:.0f} %", ""),
        ("4", "share in linear algebra",
         f"{100 * sum(v for k, v in t.total.items() if k.startswith('linalg.')) / b['wall']:.0f} %", ""),
    ]
    cpus = study["cpus"]
    rows += [
        ("5", f"study of {study['samples']} curves, one process", f"{study[1]['per_minute']:.0f} /min", ""),
        ("5", f"study of {study['samples']} curves, {cpus} local processes", f"{study[cpus]['per_minute']:.0f} /min",
         ""),
        ("5", "local processes / one process (samples per minute)", f"{study['speedup']:.2f}x", ""),
        ("5", "compile share of the samples' time, one process / processes",
         f"{100 * study[1]['compile_fraction']:.0f} / {100 * study[cpus]['compile_fraction']:.0f} %", ""),
    ]
    first, warm = large["command"][0], large["command"][-1]
    structured = [c for c in large["cases"] if c["operator"] == "structured"]
    rows += [
        ("7", "H = 2048 solve, whole process, compiled programs from the disk cache", f"{warm['wall_s']:.1f} s",
         "<= 10 s"),
        ("7", "the same, first run (compiling into an empty cache)", f"{first['wall_s']:.1f} s", ""),
        ("7", "H = 2048 solve, peak resident memory (largest run)",
         f"{max(c['rss_mb'] for c in large['command']):.0f} MB", "<= 2 GB"),
        ("7", "Newton step vs H, log-log slope (structured, H = 64 .. 2048)",
         f"{bench_large_harmonics.slope(structured):.2f}", "<= 1.3"),
    ]
    rows += _command_rows(commands, hbd, others)
    for coupling, r in bear.items():
        rows += [("8", f"{coupling} per continuation point, 8 DOF / 2 DOF (auto path)",
                  f"{r['point_ratio'][8, 'auto']:.2f}x", "<= 4x"),
                 ("8", f"{coupling} per continuation point, 8 DOF / 2 DOF (dense path)",
                  f"{r['point_ratio'][8, 'dense']:.2f}x", ""),
                 ("8", f"{coupling} per continuation point, 6 DOF / 2 DOF (auto path)",
                  f"{r['point_ratio'][6, 'auto']:.2f}x", ""),
                 ("8", f"{coupling} per curve (the same range), 8 DOF / 2 DOF (auto path)",
                  f"{r['curve_ratio'][8]:.2f}x", ""),
                 ("8", f"{coupling} per Hill evaluation, 8 DOF / 2 DOF", f"{r['hill_ratio'][8]:.2f}x", "")]
    print("\n## summary (one run, this machine)")
    print(f"{'#':2s} {'measure':58s} {'measured':>18s} {'goal':>9s}")
    for r in rows:
        print(f"{r[0]:2s} {r[1]:58s} {r[2]:>18s} {r[3]:>9s}")
    print(f"\nwall time of the benchmark run: {time.perf_counter() - t0:.0f} s; {machine()}")
    return 0


def _command_rows(commands, hbd, others) -> list[tuple]:
    """The summary rows of section 6 (and the Duffing ratios against every other tool)."""
    n, lt, hp = commands["nltv"], commands["ltv"], commands["help"]
    with_hill = 1e3 * (hbd["curve_s"] + hbd["hill_s"]) / hbd["points"]
    rows = [
        ("6", f"NLTV frc whole command per point vs TI DOP853 (median of {len(n['wall_all_s'])})",
         f"{n['speedup_per_point']:.0f}x", ">= 1000x"),
        ("6", "  whole command / its points; TI per point", f"{n['per_point_ms']:.2f} ms; {n['ti_per_point_s']:.2f} s", ""),
        ("6", "  stability on every point / continuation (same run)", f"{n['stability_over_continuation']:.2f}x", "<= 1x"),
        ("6", "  HB vs TI DTE; multipliers vs DOP853: command, Hill",
         f"{100 * n['dte_rel_rms_max']:.3f} %; {n['route_vs_dop853_max']:.0e}, {n['hill_vs_variational_max']:.0e}", ""),
        ("6", "LTV frc warm / import jax (median of pairs)", f"{lt['ratio']:.2f}x", "<= 2x"),
        ("6", "LTV frc first run, empty cache / import jax", f"{lt['cold_ratio']:.2f}x", "<= 5x"),
        ("6", "hbgear --help / import jax", f"{hp['ratio']:.2f}x", "<= 0.3x"),
    ]
    for r in others:
        rows.append(("6", f"Duffing with Hill vs {r['tool'][:40]}", f"{r['per_point_ms'] / with_hill:.1f}x", ">= 15x"))
    return rows


if __name__ == "__main__":
    sys.exit(main())
