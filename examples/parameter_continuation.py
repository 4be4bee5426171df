"""Continuation in the input torque at a fixed speed, with backlash near the primary resonance.

    python examples/parameter_continuation.py [RPM]     # from the repo root, ~30 s

examples/backlash.toml (no friction) with the backlash cut to 5 um. While the teeth only lose contact
the response is positively homogeneous (DTE - b scales with the torque exactly); once they hit the
back flank (DTE < -b) it is not. The parameter is
any float field of the model via GearSystem(model, omega_pinion=..., parameter=...), here
"torque_pinion_Nm" (use parameter="mu0" for the friction coefficient). Plot in
examples/out/parameter_continuation.png.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hbgear

rpm = float(sys.argv[1]) if len(sys.argv) > 1 else 12500.0
t_start, t_stop = 400.0, 40.0  # pinion torque range [N m]
model = hbgear.build_model(hbgear.load_config("examples/backlash.toml", ["mesh.backlash_um=5"]))
model = model.replace(torque_pinion_Nm=t_start)
start = hbgear.solve(model, speed_rpm=rpm, harmonics=24, samples=512, stability=False)  # the staged start

# the gear pair as a periodic system in another parameter: the same calls as for any system
system = hbgear.GearSystem(model, omega_pinion=start.omega_pinion, parameter="torque_pinion_Nm")
curve = hbgear.frequency_response(system, parameter=(t_start, t_stop), harmonics=24, samples=512, z0=start.z,
                                  stability=False, progress=True)
branch, hb = curve.branch, curve.hb
print(f"{branch.status.name}: {len(branch)} points, folds at {np.round(curve.folds, 1)} N m")

# DTE (coefficients z are in units of the start model's static deflection N/k_mean)
scale = system.displacement_scale
phase = np.linspace(0.0, 1.0, 512, endpoint=False)
k = np.arange(1, hb.harmonics + 1)
z = branch.z[:, : hb.block] * scale
dte = z[:, :1] + z[:, 1::2] @ np.cos(2 * np.pi * np.outer(k, phase)) + z[:, 2::2] @ np.sin(2 * np.pi * np.outer(k, phase))
back = dte.min(axis=1) < -0.5 * model.backlash_m  # back-flank contact somewhere in the period

fig, ax = plt.subplots(figsize=(8, 4.5))
ax.plot(branch.p, 1e6 * np.ptp(dte, axis=1), "k-", label="DTE peak-to-peak")
ax.plot(branch.p[back], 1e6 * np.ptp(dte, axis=1)[back], "r.", ms=4, label="back-flank contact")
ax.set(xlabel="pinion torque [N m]", ylabel="[um]")
ax.set_title(f"backlash 5 um, {rpm:g} rpm: continuation in torque")
ax.legend()
fig.tight_layout()
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/parameter_continuation.png", dpi=110)
