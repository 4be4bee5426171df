"""Frequency-response curve of the reference pair over its primary resonance (arc-length continuation).

    python examples/frc_reference.py        # from the repository root, ~30 s

Calls the `hbgear frc` command (the same as `hbgear frc examples/paper_table1.toml --set ...`),
which writes frc.csv, frc.json and frc.png into examples/out/frc_reference/, then redraws the
curve with the mesh frequency on a second axis as examples/out/frc_reference.png.
"""

import csv
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from hbgear.cli import main

OUT = Path("examples/out")
status = main([
    "frc", "examples/paper_table1.toml", "--out", str(OUT / "frc_reference"), "--no-progress",
    "--set", "sweep.speed_rpm_start=9000", "--set", "sweep.speed_rpm_stop=17000",
    "--set", "solver.harmonics=16", "--set", "solver.time_samples=64",
    "--set", "boundary.output='torques'",  # the DTE alone: faster; 'spring' gives the same DTE
])
if status != 0:
    raise SystemExit(status)

rows = list(csv.DictReader(open(OUT / "frc_reference" / "frc.csv")))
info = json.loads((OUT / "frc_reference" / "frc.json").read_text())
rpm = [float(r["speed_rpm"]) for r in rows]
p2p = [float(r["dte_p2p_um"]) for r in rows]
unstable = [(x, y) for x, y, r in zip(rpm, p2p, rows) if r["stable"] == "0"]

fig, ax = plt.subplots(figsize=(8, 4.5))
ax.plot(rpm, p2p, "k-", lw=1, label=f"HB continuation, H={info['harmonics']}")
if unstable:
    ax.plot(*zip(*unstable), "r.", ms=3, label="unstable (Floquet)")
ax.set_xlabel("pinion speed [rpm]")
ax.set_ylabel("DTE peak-to-peak [um]")
top = ax.secondary_xaxis("top", functions=(lambda r: r * 25 / 60, lambda f: f * 60 / 25))
top.set_xlabel("mesh frequency [Hz]")
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "frc_reference.png", dpi=110)
print(f"{info['points']} points in {info['timings_s']['total']:.1f} s, peak {info['peak']['dte_p2p_um']:.2f} um "
      f"at {info['peak']['speed_rpm']:.0f} rpm -> {OUT / 'frc_reference.png'}")
