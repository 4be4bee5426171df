"""Stability map: max |Floquet multiplier| over speed x contact ratio (paper Fig. 13 in kind).

    python examples/stability_map.py     # from the repo root, ~5 s

LTV formulation A, single-coordinate `torques` boundary: exact monodromy (products of matrix
exponentials), k_max and k_min held as the contact ratio varies. The same as
`hbgear stability-map examples/paper_table1.toml --set boundary.output='torques'`.
Plot in examples/out/stability_map.png.
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from hbgear.config import load_config
import hbgear

cfg = load_config("examples/paper_table1.toml", ["boundary.output='torques'", "friction.model='LTV'"])
speeds = np.linspace(20000.0, 32000.0, 121)  # [rpm]
ratios = np.linspace(1.35, 1.65, 31)
grid = hbgear.stability_map(cfg, speeds, ratios)  # (ratios, speeds): exact monodromy for LTV-A
print(f"unstable fraction of the grid: {np.mean(grid > 1):.3f}; largest |multiplier| {grid.max():.4f}")

fig, ax = plt.subplots(figsize=(8, 4.5))
mesh = ax.pcolormesh(speeds, ratios, grid, shading="auto", cmap="viridis")
ax.contour(speeds, ratios, grid, levels=[1.0], colors="r")
fig.colorbar(mesh, label="max |multiplier| per mesh period")
ax.set_xlabel("pinion speed [rpm]")
ax.set_ylabel("contact ratio")
ax.set_title("LTV-A, zeta 0.01: red = stability boundary (inside unstable)")
fig.tight_layout()
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/stability_map.png", dpi=110)
