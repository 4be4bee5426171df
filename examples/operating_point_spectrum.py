"""One operating point by harmonic balance: DTE waveform and spectrum, with the read-outs.

    python examples/operating_point_spectrum.py [RPM]     # from the repo root, ~10 s

Reference pair, NLTV friction (instantaneous sliding velocity), soft output spring; plot in
examples/out/operating_point_spectrum.png.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hbgear

rpm = float(sys.argv[1]) if len(sys.argv) > 1 else 4500.0
cfg = hbgear.load_config("examples/paper_table1.toml", ["friction.model='NLTV'", "boundary.damping_ratio=0.1"])
model = hbgear.build_model(cfg)
sol = hbgear.solve(model, speed_rpm=rpm, harmonics=cfg.solver.harmonics, samples=cfg.solver.time_samples)

for key, value in sol.summary().items():
    print(f"{key:24s} {value:12.5g}")

phase = np.linspace(0.0, 2.0, 801)  # two mesh periods
q, _ = sol.state_at(phase % 1.0)
table = np.array(sol.harmonic_table())  # (order, amplitude_um, phase_deg)

fig, (ax_t, ax_f) = plt.subplots(1, 2, figsize=(11, 4))
ax_t.plot(phase, 1e6 * q[0], "k")
ax_t.set_xlabel("time / mesh period")
ax_t.set_ylabel("DTE [um]")
ax_f.bar(table[1:, 0], table[1:, 1], width=0.4)
ax_f.set_yscale("log")
ax_f.set_xlabel("mesh order")
ax_f.set_ylabel("DTE amplitude [um]")
fig.suptitle(f"NLTV, {rpm:g} rpm, H={sol.harmonics}: rms {sol.summary()['dte_rms_um']:.3f} um")
fig.tight_layout()
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/operating_point_spectrum.png", dpi=110)
