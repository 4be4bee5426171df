"""A user-defined non-linear system: two masses, the second rubbing on the ground (dry friction).

    python examples/friction_oscillator.py        # from the repository root, ~30 s

    m x1'' + c x1' + k x1 + k (x1 - x2) = f cos(w t)
    m x2'' + c x2' + k x2 + k (x2 - x1) + mu N tanh(x2' / v_eps) = 0

The regularised Coulomb force (a smooth tanh law; ``v_eps`` small) is the non-linear part, evaluated
by alternating frequency-time; the frequency-response curve over both modes comes from the same
call as the gear pair's, with Floquet stability by Hill's method. An independent check written
here with SciPy alone integrates the equations in time to steady state at three frequencies and
compares the amplitude of x1 (H = 21 is within 0.05 %; the stick-slip corners of x2 need more
harmonics for more digits: H = 81 within 1e-5). Plot in examples/out/friction_oscillator.png.
"""

from dataclasses import dataclass
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")
import numpy as np
from scipy.integrate import solve_ivp

import hbgear


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class FrictionOscillator(hbgear.PeriodicSystem):
    """Two masses (m), three springs (k), light dampers (c); mass 2 rubs with mu N tanh(v / v_eps)."""

    mass: float = 1.0
    stiffness: float = 1.0
    damping: float = 0.01
    forcing: float = 0.2
    friction: float = 0.05  # mu N [N]
    v_eps: float = 1e-2  # regularisation speed [m/s]

    ndof = 2
    is_linear = False
    coefficients_independent_of_parameter = True
    forcing_affine_in_frequency = True
    nonlinear_force_uses_displacement = False  # the friction force depends on x2' only

    def mass_matrix(self, p, xp=np):
        return self.mass * xp.eye(2)

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        k, c = self.stiffness, self.damping
        linear = xp.stack([self.forcing * xp.cos(2 * np.pi * s) - k * q[0] - k * (q[0] - q[1]) - c * qd[0],
                           -k * q[1] - k * (q[1] - q[0]) - c * qd[1]])
        rub = xp.stack([0.0 * qd[0], -self.friction * xp.tanh(qd[1] / self.v_eps)])
        return {"linear": linear, "nonlinear": rub, "all": linear + rub}[part]


def time_integration_amplitude(system: FrictionOscillator, w: float, periods: int = 400) -> float:
    """max |x1| over the last period, by DOP853 from rest (independent of hbgear)."""
    m, k, c = system.mass, system.stiffness, system.damping

    def rhs(t, y):
        x1, x2, v1, v2 = y
        a1 = (system.forcing * np.cos(w * t) - k * x1 - k * (x1 - x2) - c * v1) / m
        a2 = (-k * x2 - k * (x2 - x1) - c * v2 - system.friction * np.tanh(v2 / system.v_eps)) / m
        return [v1, v2, a1, a2]

    T = 2 * np.pi / w
    sol = solve_ivp(rhs, (0, periods * T), [0, 0, 0, 0], method="LSODA", rtol=1e-10, atol=1e-12,
                    t_eval=np.linspace((periods - 1) * T, periods * T, 801))
    return float(np.max(np.abs(sol.y[0])))


system = FrictionOscillator()
curve = hbgear.frequency_response(system, parameter=(0.6, 2.2), harmonics=21, samples=512, progress=False)
print(f"{len(curve)} points, {len(curve.folds)} folds, {int(np.sum(curve.stable == 0))} unstable points")
checks = []
for w in (0.9, 1.4, 1.9):
    z21 = curve.z[np.argmin(np.abs(curve.parameter - w))]
    hb21 = hbgear.solve(system, parameter=w, harmonics=21, samples=512, z0=z21, stability=False)
    z81 = np.pad(hb21.z.reshape(2, -1), ((0, 0), (0, 120))).ravel()  # the same waveform in H = 81
    hb81 = hbgear.solve(system, parameter=w, harmonics=81, samples=1024, z0=z81, stability=False)
    ti = time_integration_amplitude(system, w)
    checks.append((w, hb21.max_abs(0), ti))
    print(f"w = {w}: max|x1| time integration {ti:.7g}; HB H=21 {hb21.max_abs(0):.7g} "
          f"({hb21.max_abs(0) / ti - 1:+.1e}), H=81 {hb81.max_abs(0):.7g} ({hb81.max_abs(0) / ti - 1:+.1e})")

fig = curve.plot(coordinate=0, title="two masses, dry friction on the second: max |x1(t)|")
ax = fig.axes[0]
ax.plot([c[0] for c in checks], [c[2] for c in checks], "s", mfc="none", color="tab:orange", label="time integration")
ax.legend(fontsize=8)
Path("examples/out").mkdir(parents=True, exist_ok=True)
fig.savefig("examples/out/friction_oscillator.png", dpi=110)
print("-> examples/out/friction_oscillator.png")
