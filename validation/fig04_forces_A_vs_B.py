"""Paper Fig. 4: mesh and friction forces per pair, formulation A (quasi-static load) vs B
(dynamic mesh force); Gamma = 1.532, mu0 = 0.1, zeta = 0.01, 2400 rpm, LTV, soft-spring output.

Writes ``validation/out/fig04.png`` and ``validation/out/fig04.md``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hbgear.build import build_model
from hbgear.config import parse_config
from hbgear.gear.simulate import simulate

OUT = Path(__file__).resolve().parent / "out"
BASE = {
    "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.532,
                 inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
    "mesh": dict(k_max_MN_per_m=720.0, k_mean_MN_per_m=568.0, damping_ratio=0.01),
    "load": dict(torque_pinion_Nm=226.0),
    "friction": dict(law="coulomb", mu0=0.1, model="LTV"),
    "boundary": dict(output="spring", damping_ratio=0.0),
}
RPM = 2400.0


def run(rpm: float = RPM):
    results = {}
    for form in ("A", "B"):
        data = {k: dict(v) for k, v in BASE.items()}
        data["friction"]["formulation"] = form
        results[form] = simulate(build_model(parse_config(data)), rpm * math.pi / 30)
    return results


def plot_and_note(results, out=OUT):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    lines = []
    for col, form in enumerate(("A", "B")):
        r = results[form]
        phase = r.t / r.mesh_period_s - r.t[0] / r.mesh_period_s
        contact = r.pairs["sigma"] > 0
        axes[0, col].plot(phase, r.mesh_force, "k", label="F_mesh")
        for k in range(2):
            axes[0, col].plot(phase, np.where(contact[k], r.pairs["normal"][k], np.nan), label=f"N, pair slot {k + 1}")
            axes[1, col].plot(phase, np.where(contact[k], r.pairs["friction"][k], np.nan), label=f"mu N, pair slot {k + 1}")
        axes[0, col].set_title(f"formulation {form}")
        axes[1, col].set_xlabel("time / mesh period")
        axes[0, col].legend(fontsize=7)
        axes[1, col].legend(fontsize=7)
        fr = np.where(contact, r.pairs["friction"], np.nan)
        lines.append(
            f"| {form} | {r.summary['dte_rms_um']:.4f} | {r.summary['dte_p2p_um']:.4f} | "
            f"{r.summary['dynamic_factor']:.4f} | {np.nanmin(fr):.1f} .. {np.nanmax(fr):.1f} | "
            f"{r.summary['mean_friction_loss_W']:.1f} | {r.cycles} |"
        )
    axes[0, 0].set_ylabel("normal / mesh force [N]")
    axes[1, 0].set_ylabel("friction force [N]")
    fig.suptitle(f"Fig. 4 analogue: Gamma 1.532, mu0 0.1, zeta 0.01, {results['A'].speed_rpm:.0f} rpm (LTV)")
    fig.tight_layout()
    fig.savefig(out / "fig04.png", dpi=110)
    plt.close(fig)
    a, b = results["A"], results["B"]
    dfa = np.nanmax(np.abs(np.where(a.pairs["sigma"] > 0, a.pairs["friction"], np.nan)))
    note = f"""# Fig. 4 -- mesh and friction forces per pair, formulation A vs B

Case: Gamma = 1.532, mu0 = 0.1 (Coulomb, nominal sliding: LTV), zeta = 0.01, {a.speed_rpm:.0f} rpm,
soft-spring output, time integration (hbgear.gear.simulate) to steady state.

| formulation | DTE rms [um] | DTE p2p [um] | dynamic factor | friction force range [N] | friction loss [W] | cycles |
|---|---|---|---|---|---|---|
""" + "\n".join(lines) + f"""

What matches the paper in kind:
- A: the friction force of each pair is piecewise constant, mu0 sigma_j N = {0.1 * a.pairs['normal'].max() / 2:.0f} N in
  double contact and {dfa:.0f} N in single contact, reversing sign at the pitch point (Fig. 4a). These
  levels hold by construction (formulation A's load is sigma_j N with the nominal sliding direction):
  a check of the code, not evidence.
- B: the friction force follows the dynamic mesh force (it carries the mesh-frequency ripple
  and the jumps at pair entry/exit), as in Fig. 4b; the DTE differs only slightly between A
  and B at this speed (rms {a.summary['dte_rms_um']:.4f} vs {b.summary['dte_rms_um']:.4f} um).

What does not / cannot match: absolute levels depend on the completed Table 1 values (MODEL.md);
the paper's plots are not digitised here, so only the shapes are compared.
"""
    (out / "fig04.md").write_text(note)
    return note


if __name__ == "__main__":
    print(plot_and_note(run()))
