"""Time integration to steady state: DTE, mesh force and the friction force of each tooth pair.

    python examples/time_simulation.py [RPM]     # from the repo root, ~15 s

Reference pair with formulation B (friction from the dynamic mesh force), NLTV, soft output
spring with a light damper so the soft mode settles. Plot in examples/out/time_simulation.png.
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hbgear

rpm = float(sys.argv[1]) if len(sys.argv) > 1 else 3000.0
overrides = ["friction.model='NLTV'", "friction.formulation='B'", "boundary.damping_ratio=0.1"]
model = hbgear.build_model(hbgear.load_config("examples/paper_table1.toml", overrides))
res = hbgear.simulate(model, speed_rpm=rpm, progress=True)
print(f"steady after {res.cycles} mesh cycles ({res.elapsed_s:.1f} s); summary:")
for key, value in res.summary.items():
    print(f"  {key:24s} {value:12.5g}")

x = (res.t - res.t[0]) / res.mesh_period_s
fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
axes[0].plot(x, 1e6 * res.q[0], "k")
axes[0].set_ylabel("DTE [um]")
axes[1].plot(x, 1e-3 * res.mesh_force, "k")
axes[1].set_ylabel("mesh force [kN]")
for k in range(res.pairs["friction"].shape[0]):
    contact = res.pairs["sigma"][k] > 0
    axes[2].plot(x, np.where(contact, res.pairs["friction"][k], np.nan), label=f"pair slot {k + 1}")
axes[2].set_ylabel("friction force mu N [N]")
axes[2].set_xlabel("time / mesh period")
axes[2].legend(fontsize=8)
fig.suptitle(f"NLTV-B, {rpm:g} rpm (time integration)")
fig.tight_layout()
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/time_simulation.png", dpi=110)
