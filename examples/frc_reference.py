"""Frequency-response curve of the reference pair over its primary resonance, from Python.

    python examples/frc_reference.py        # from the repository root, ~15 s

The same computation as `hbgear frc examples/paper_table1.toml --set ...` through the Python API:
the curve's arrays, its folds, period doublings and unstable zones, and its figure (with the mesh
frequency on the top axis) as examples/out/frc_reference.png.
"""

from pathlib import Path

import numpy as np

import hbgear

config = hbgear.load_config("examples/paper_table1.toml", ["boundary.output='torques'"])  # the DTE alone: faster
model = hbgear.build_model(config)
curve = hbgear.frequency_response(model, speed_rpm=(9000.0, 17000.0), harmonics=16, samples=64, progress=False)

peak = int(np.argmax(curve.dte_p2p_um))
print(f"{curve.points} points, peak DTE p2p {curve.dte_p2p_um[peak]:.2f} um at {curve.speed_rpm[peak]:.0f} rpm "
      f"({curve.mesh_freq_hz[peak]:.0f} Hz); {int(np.sum(curve.stable == 0))} unstable points; "
      f"folds at {np.round(curve.folds, 1)} rpm")
for zone in curve.unstable_zones:
    print(f"unstable zone {zone['speed_rpm_from']:.1f}-{zone['speed_rpm_to']:.1f} rpm "
          f"(leaves through {zone['leaves_through']}, max |multiplier| {zone['max_abs_floquet']:.4f})")
Path("examples/out").mkdir(parents=True, exist_ok=True)
curve.plot().savefig("examples/out/frc_reference.png", dpi=110)
print("-> examples/out/frc_reference.png")
