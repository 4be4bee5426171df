"""Paper Fig. 7: net input power. With constant torques on both gears its mean is zero (friction
cannot be balanced); with the soft output spring the mean equals the friction loss plus the mean
mesh power <F_mesh delta'> (MODEL.md section 4). Reference pair, LTV, Coulomb mu0 = 0.1.

Writes ``validation/out/fig07.png`` and ``validation/out/fig07.md``.
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
    "gear": dict(teeth_pinion=25, teeth_gear=31, module_mm=3.175, contact_ratio=1.433,
                 inertia_pinion_kgm2=1.0594e-3, inertia_gear_kgm2=2.5047e-3),
    "mesh": dict(k_max_MN_per_m=720.0, k_mean_MN_per_m=568.0, damping_ratio=0.01),
    "load": dict(torque_pinion_Nm=226.0),
    "friction": dict(law="coulomb", mu0=0.1, model="LTV", formulation="A"),
}
RPM = 3000.0


def net_power(res, model):
    """Instantaneous net input power ``T_p (Omega_p + theta_p') - T_out (Omega_g + theta_g')`` [W]."""
    wp, wg, _ = model.speeds(res.omega_pinion)
    if model.boundary == "torques":  # one coordinate: only delta' is known, theta' about nominal
        return model.normal_load_N * res.qd[0]
    rbp, rbg = model.base_radius_pinion_m, model.base_radius_gear_m
    p_in = model.torque_pinion_Nm * (wp + (res.qd[0] + res.qd[1]) / rbp)
    t_out = rbg * (model.spring_stiffness_N_per_m * (res.q[1] + res.u_static) + model.spring_damping_Ns_per_m * res.qd[1])
    return p_in - t_out * (wg + res.qd[1] / rbg)


def run(rpms=(RPM, 2000.0)):
    out = {}
    for output in ("torques", "spring"):
        data = {k: dict(v) for k, v in BASE.items()}
        data["boundary"] = {"output": output, "damping_ratio": 0.0}
        model = build_model(parse_config(data))
        for rpm in rpms if output == "spring" else rpms[:1]:
            res = simulate(model, rpm * math.pi / 30)
            out[(output, rpm)] = (model, res, net_power(res, model))
    return out


def plot_and_note(results, out=OUT):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    keys = [k for k in results if k[1] == RPM]
    fig, axes = plt.subplots(len(keys), 1, figsize=(9, 6), sharex=True)
    rows = []
    for ax, key in zip(axes, keys):
        model, res, p = results[key]
        phase = (res.t - res.t[0]) / res.mesh_period_s
        ax.plot(phase, 1e-3 * p, "k")
        ax.axhline(1e-3 * np.mean(p), color="r", ls="--", label=f"grid mean {np.mean(p):.1f} W")
        ax.set_ylabel("net input power [kW]")
        ax.set_title(f"boundary '{key[0]}'")
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("time / mesh period")
    fig.suptitle(f"Fig. 7 analogue: net input power, reference pair, LTV mu0 0.1, {RPM:.0f} rpm")
    fig.tight_layout()
    fig.savefig(out / "fig07.png", dpi=110)
    plt.close(fig)
    for key, (model, res, p) in results.items():
        s = res.summary
        rows.append(
            f"| {key[0]} | {key[1]:.0f} | {s['mean_power_loss_W']:.3f} | {s['mean_friction_loss_W']:.3f} | "
            f"{s['mean_mesh_power_W']:.3f} | {s['mean_power_loss_W'] - s['mean_friction_loss_W'] - s['mean_mesh_power_W']:.2e} |"
        )
    spring = {k[1]: v[1].summary["mean_friction_loss_W"] for k, v in results.items() if k[0] == "spring"}
    slope = spring[RPM] / RPM
    note = """# Fig. 7 -- net input power, constant torques vs soft output spring

Reference pair (Table 1 completed, Gamma 1.433), LTV, Coulomb mu0 = 0.1, formulation A, zeta 0.01,
boundary damping ratio 0 (the soft mode is deflated by the integrator, see hbgear.gear.simulate).
Means are quadrature means over one steady period (hbgear.gear.readouts.periodic_summary).

| boundary | speed [rpm] | mean net power (loss) [W] | friction loss [W] | mesh power <F delta'> [W] | loss - friction - mesh [W] |
|---|---|---|---|---|---|
""" + "\n".join(rows) + f"""

What matches the paper: with constant torques the net input power oscillates about a zero
mean (friction is not balanced: the rigid-body speed would drift; the zero mean holds by
construction, T_g = T_p R_bg/R_bp at the nominal speeds of the DTE-only model); with the soft spring the
mean net power equals the friction loss plus the mesh power to rounding (balance error above).
The mesh power is small and may be negative: it is the viscous loss plus the work of the
jumping stiffness, <k(t) delta delta'>, which is not zero when k jumps.

The paper's 629 W is for its own (incompletely specified) case and speed. Here the friction
loss is proportional to speed, {slope:.4f} W/rpm ({spring[RPM]:.1f} W at {RPM:.0f} rpm,
{spring.get(2000.0, float('nan')):.1f} W at 2000 rpm), so 629 W corresponds to about
{629 / slope:.0f} rpm for the reference pair (for LTV with formulation A the friction loss is
exactly the quasi-static mu0 <sum_j sigma_j N |Vs_j|> at nominal sliding, hence linear in
speed; the small departure at 2000 rpm comes from the soft mode's u' in the output power).
"""
    (out / "fig07.md").write_text(note)
    return note


if __name__ == "__main__":
    print(plot_and_note(run()))
