"""A user-defined periodic system: the damped Mathieu oscillator and its stability chart.

    python examples/parametric_oscillator.py      # from the repository root, ~20 s

    x'' + 2 zeta x' + (1 + eps cos(w t)) x = f cos(w t)

is written as a `hbgear.PeriodicSystem` (its parameter is the excitation frequency `w`), solved
and continued with the same calls as the gear pair, and its Floquet multipliers give the
principal parametric instability tongue around w = 2 (Ince-Strutt chart). For small eps and no
damping the tongue's edges are w = 2 -/+ eps/2 + O(eps^2) (first-order averaging of the Mathieu
equation); with damping the tongue closes below eps = 4 zeta. Plot in
examples/out/parametric_oscillator.png.
"""

from dataclasses import dataclass
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import hbgear


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Mathieu(hbgear.PeriodicSystem):
    """``x'' + 2 zeta x' + (1 + eps cos(w t)) x = f cos(w t)``; parameter ``w`` [rad/s]."""

    zeta: float = 0.01
    eps: float = 0.2
    forcing: float = 0.01

    ndof = 1
    is_linear = True  # the stiffness is periodic, but the equation is linear in x
    coefficients_independent_of_parameter = True  # w only scales time: M, K(s), C do not depend on it
    forcing_affine_in_frequency = True

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        c = xp.cos(2 * np.pi * s)
        linear = self.forcing * c - (1.0 + self.eps * c) * q[0] - 2 * self.zeta * qd[0]
        return xp.stack([linear if part != "nonlinear" else 0.0 * linear])


# one frequency-response curve through the tongue: unstable points between the edges
curve = hbgear.frequency_response(Mathieu(), parameter=(1.6, 2.4), harmonics=12, progress=False)
edges = curve.parameter[np.flatnonzero(np.diff(curve.stable) != 0)]
print(f"{len(curve)} points; stability changes at w = {np.round(edges, 4)} (first order, no damping: "
      f"{2 - 0.1:.3f}, {2 + 0.1:.3f})")

# the chart: max |multiplier| over (w, eps) by exact monodromy (the system is linear)
from hbgear.engine.monodromy import multipliers_linear  # noqa: E402

freqs = np.linspace(1.6, 2.4, 161)
amps = np.linspace(0.0, 0.6, 61)
chart = np.array([np.abs(multipliers_linear(Mathieu(eps=e), freqs)).max(axis=1) for e in amps])

fig, (ax_c, ax_m) = plt.subplots(1, 2, figsize=(11, 4))
ax_c.plot(curve.parameter, curve.max_abs(0), "k-", lw=1, label="HB continuation")
bad = curve.stable == 0
ax_c.plot(curve.parameter[bad], curve.max_abs(0)[bad], "r.", ms=3, label="unstable (Floquet)")
ax_c.set_xlabel("excitation frequency w")
ax_c.set_ylabel("max |x(t)|")
ax_c.set_yscale("log")
ax_c.legend()
mesh = ax_m.pcolormesh(freqs, amps, chart, shading="auto", cmap="RdBu_r", vmin=0.8, vmax=1.2)
ax_m.contour(freqs, amps, chart, levels=[1.0], colors="k")
ax_m.plot(2 - amps / 2, amps, "g--", lw=1, label="w = 2 -/+ eps/2 (no damping, first order)")
ax_m.plot(2 + amps / 2, amps, "g--", lw=1)
ax_m.set_xlabel("excitation frequency w")
ax_m.set_ylabel("eps")
ax_m.legend(fontsize=8, loc="upper right")
fig.colorbar(mesh, ax=ax_m, label="max |multiplier|")
fig.tight_layout()
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/parametric_oscillator.png", dpi=110)
print("-> examples/out/parametric_oscillator.png")
