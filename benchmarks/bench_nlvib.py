r"""The Duffing curve of :mod:`bench_duffing_tools` by NLvib 1.3 (M. Krack, J. Gross) under GNU Octave.

NLvib is MATLAB code (GPL) and is not part of hbgear: this script runs a local copy given as
``--nlvib DIR`` (the directory with ``SRC/solve_and_continue.m``). The copy is not changed: its
``SRC`` is copied to a temporary directory, where the one line NLvib's README says Octave needs
changed (``optimset(@fsolve)`` -> ``optimset("fsolve")``) is changed, and a driver script runs
there. GNU Octave (``octave-cli``) must be installed (on Debian: ``apt-get install octave``);
:func:`ensure_octave` installs it with apt when it is missing and says so.

Problem and settings as for the other tools: ``x'' + 0.02 x' + x + 0.1 x^3 = 0.05 cos w t``,
``w`` in ``[0.5, 2]``, ``H = 7``, ``N = 64``; NLvib's generic ``HB_residual`` (analytic
Jacobian) on a ``SingleMassOscillator`` with a ``cubicSpring``, its ``solve_and_continue``
(arc length, MATLAB/Octave ``fsolve``), the step size set so that it stores about as many
points as asked. NLvib has no stability computation. Timings: Octave's ``tic``/``toc`` around
``solve_and_continue``, the median of ``repeats`` runs after a first one (reported apart).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from bench_duffing_tools import CUBIC, DAMPING, FORCING, H, SAMPLES, STIFFNESS, W0, W1

DRIVER = r"""
addpath('{src}'); addpath('{src}/MechanicalSystems');
warning('off', 'all');
ne{{1}} = struct('type', 'cubicSpring', 'stiffness', {cubic}, 'force_direction', 1);
osc = SingleMassOscillator(1, {damping}, {stiffness}, ne, {forcing});
H = {harmonics}; N = {samples}; Om_s = {w0}; Om_e = {w1};
Q1 = (-Om_s^2*osc.M + 1i*Om_s*osc.D + osc.K)\osc.Fex1;
y0 = zeros(2*H+1, 1); y0(2:3) = [real(Q1); -imag(Q1)];
Sopt = struct('Dscale', [ones(size(y0)); Om_s], 'stepmax', 100000, 'dsmax', {ds_max});
times = zeros(1, {runs});
for r = 1:{runs}
  tic;
  [X, info] = solve_and_continue(y0, @(X) HB_residual(X, osc, H, N, 'FRF'), Om_s, Om_e, {ds}, Sopt);
  times(r) = toc;
end
fid = fopen('{out}', 'w');
fprintf(fid, '{{"times": [%s], "points": %d, "x": [%s]}}', strjoin(arrayfun(@(t) sprintf('%.6f', t), times, ...
        'UniformOutput', false), ','), size(X, 2), strjoin(arrayfun(@(v) sprintf('%.17g', v), X(:)', ...
        'UniformOutput', false), ','));
fclose(fid);
"""


def ensure_octave() -> tuple[str, str | None]:
    """``(octave-cli path, note)``: installs Debian's ``octave`` with apt-get when it is missing
    (the note says so); raises ``RuntimeError`` when that fails."""
    found = shutil.which("octave-cli")
    if found:
        return found, None
    apt = shutil.which("apt-get")
    if apt is None:
        raise RuntimeError("octave-cli not found and no apt-get to install it")
    for args in (["update"], ["install", "-y", "--no-install-recommends", "octave"]):
        done = subprocess.run([apt, *args], capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"apt-get {' '.join(args)} failed: {done.stderr.strip().splitlines()[-1:]}")
    found = shutil.which("octave-cli")
    if not found:
        raise RuntimeError("apt-get installed octave but octave-cli is not on PATH")
    return found, "GNU Octave was not installed: installed Debian's octave package with apt-get for this run"


def _version(nlvib: Path) -> str:
    text = (nlvib / "SRC" / "solve_and_continue.m").read_text(errors="replace")
    return "1.3" if "NLvib Version 1.3" in text else "?"


def run_once(octave: str, src: Path, work: Path, ds: float, runs: int) -> dict:
    """One Octave process: `runs` continuations with step size `ds`; the times, points and X."""
    out = work / "result.json"
    script = work / "driver.m"
    script.write_text(DRIVER.format(src=src, cubic=CUBIC, damping=DAMPING, stiffness=STIFFNESS, forcing=FORCING,
                                    harmonics=H, samples=SAMPLES, w0=W0, w1=W1, ds=ds, ds_max=5 * ds, runs=runs,
                                    out=out))
    done = subprocess.run([octave, "--no-gui", "--quiet", str(script)], capture_output=True, text=True, cwd=work)
    if done.returncode != 0 or not out.exists():
        tail = (done.stderr.strip().splitlines() or done.stdout.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"octave exited {done.returncode}: {tail}")
    return json.loads(out.read_text())


def run(nlvib: str | Path, target_points: int, repeats: int = 3) -> tuple[dict | None, list[str]]:
    """NLvib's Duffing curve with about `target_points` points: ``(row, notes)``, the row in the
    form of :mod:`bench_duffing_tools` (``tool``, ``points``, ``first_run_s``, ``curve_s``,
    ``w``, ``coeffs``, ...), or ``None`` and why."""
    import numpy as np

    nlvib = Path(nlvib)
    notes: list[str] = []
    if not (nlvib / "SRC" / "solve_and_continue.m").exists():
        return None, [f"NLvib not run: {nlvib} has no SRC/solve_and_continue.m"]
    try:
        octave, note = ensure_octave()
    except RuntimeError as exc:
        return None, [f"NLvib not run: {exc}"]
    if note:
        notes.append(note)
    with tempfile.TemporaryDirectory(prefix="hbgear-nlvib-") as tmp:
        work = Path(tmp)
        src = work / "SRC"
        shutil.copytree(nlvib / "SRC", src)
        solver = src / "solve_and_continue.m"
        solver.write_text(solver.read_text().replace("optimset(optimset(@fsolve)", 'optimset(optimset("fsolve")'))
        ds = 0.05
        try:
            for _ in range(6):  # the step size for about target_points points
                trial = run_once(octave, src, work, ds, 1)
                if abs(trial["points"] - target_points) <= 0.1 * target_points:
                    break
                ds *= trial["points"] / target_points
            result = run_once(octave, src, work, ds, repeats + 1)
        except RuntimeError as exc:
            return None, notes + [f"NLvib failed: {exc}"]
    x = np.asarray(result["x"], dtype=float).reshape(result["points"], 2 * H + 2)
    times = result["times"]
    row = {"tool": f"NLvib {_version(nlvib)} (Octave, fsolve, ds={ds:.3g})", "points": int(result["points"]),
           "first_run_s": float(times[0]), "curve_s": float(np.median(times[1:])), "hill_s": None,
           "unstable_points": None, "w": x[:, -1].tolist(), "coeffs": x[:, :-1].tolist(), "max_residual": float("nan")}
    notes.append(f"NLvib: median of {len(times) - 1} runs in one Octave process after a first; its SRC copied to a "
                 "temporary directory with the optimset line Octave needs (NLvib's README)")
    return row, notes


def main(argv=None):
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("nlvib", help="a local copy of NLvib (the directory with SRC/)")
    parser.add_argument("--points", type=int, default=167)
    args = parser.parse_args(argv)
    row, notes = run(args.nlvib, args.points)
    print(json.dumps({k: v for k, v in (row or {}).items() if k not in ("w", "coeffs")}, indent=1))
    for n in notes:
        print("note:", n)
    return 0 if row else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    sys.exit(main())
