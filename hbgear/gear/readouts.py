"""What a user reads out of one steady-state period (MODEL.md section 7, INTERFACE.md).

One function serves harmonic balance and time integration alike: both hand over the state at
the nodes of a quadrature rule over one steady-state period (weights summing to 1), so means
and RMS values are integrals, not sample averages, and the two routes are compared on equal
terms.

Powers (means over the period, MODEL.md section 4):

- input ``<T_p (Omega_p + theta_p')>``;
- output ``<T_out (Omega_g + theta_g')>``: ``T_out = T_g`` (torques), the spring's reaction
  ``k_b theta_g + c_b theta_g'`` (spring), the solved mean output torque (reaction);
- loss = input - output, which must equal the friction loss
  ``-<T_fp (Omega_p + theta_p') + T_fg (Omega_g + theta_g')>`` plus the mesh power
  ``<F_mesh delta'>``.

With a single DTE coordinate (torques) the rigid-body speeds are the nominal ones.
"""

from __future__ import annotations

import numpy as np

__all__ = ["periodic_summary", "SUMMARY_KEYS"]

SUMMARY_KEYS = (
    "dte_mean_um",
    "dte_rms_um",
    "dte_p2p_um",
    "dynamic_factor",
    "mean_input_power_W",
    "mean_output_power_W",
    "mean_power_loss_W",
    "mean_friction_loss_W",
    "mean_mesh_power_W",
)


def periodic_summary(model, omega_pinion, s, q, qd, weights, u_static=0.0, reaction=0.0, xp=np,
                     keys=SUMMARY_KEYS) -> dict:
    """Scalar read-outs of one steady-state period.

    **Arguments:**

    - `model`: the :class:`~hbgear.gear.model.GearPairModel`; `omega_pinion`: ``Omega_p`` [rad/s].
    - `s`: mesh phase in [0, 1) at the nodes; `q`, `qd`: state at the nodes, shape
      ``(ndof, n)`` [m], [m/s]; `weights`: quadrature weights over the period (sum 1).
    - `u_static`: the spring's static wind-up [m]; `reaction`: ``T_g/R_bg`` [N] (reaction).
    - `keys`: the read-outs wanted (a subset of :data:`SUMMARY_KEYS`; only what they need is
      evaluated: the mesh force for the dynamic factor and the mesh power, the friction for the
      powers).

    Batches: ``q``, ``qd`` of shape ``(ndof, P, n)`` with `omega_pinion`, `u_static`, `reaction`
    of shape ``(P, 1)`` and ``s`` of shape ``(1, n)`` give every read-out with shape ``(P,)``
    (means and extremes are over the last axis).

    **Returns:** a dict with `keys` (µm, W, -).
    """
    unknown = set(keys) - set(SUMMARY_KEYS)
    if unknown:
        raise ValueError(f"unknown read-outs {sorted(unknown)}; known: {SUMMARY_KEYS}")
    w = weights
    delta = q[0]
    mean = xp.sum(w * delta, axis=-1)
    rms = xp.sqrt(xp.sum(w * (delta - mean[..., None]) ** 2, axis=-1))
    out = {"dte_mean_um": 1e6 * mean, "dte_rms_um": 1e6 * rms,
           "dte_p2p_um": 1e6 * (xp.max(delta, axis=-1) - xp.min(delta, axis=-1))}
    if {"dynamic_factor", "mean_mesh_power_W"} & set(keys):
        mesh = model.mesh_force(s, q, qd, omega_pinion, xp)
        out["dynamic_factor"] = xp.max(mesh, axis=-1) / model.normal_load_N
        out["mean_mesh_power_W"] = xp.sum(w * mesh * qd[0], axis=-1)
    if set(SUMMARY_KEYS[4:8]) & set(keys):
        out.update(_powers(model, omega_pinion, s, q, qd, w, u_static, reaction, xp))
    return {k: out[k] for k in keys}


def _powers(model, omega_pinion, s, q, qd, w, u_static, reaction, xp) -> dict:
    """The mean input, output and lost powers and the friction loss of :func:`periodic_summary`."""
    delta = q[0]
    wp_tot, wg_tot = model.angular_velocities(qd, omega_pinion, nominal=False)
    t_fp, t_fg = model.friction_torques(s, q, qd, omega_pinion, xp)
    friction_loss = -xp.sum(w * (t_fp * wp_tot + t_fg * wg_tot), axis=-1)
    input_power = model.torque_pinion_Nm * xp.sum(w * wp_tot, axis=-1)
    rbg = model.base_radius_gear_m
    if model.boundary == "torques":
        output_torque = model.torque_gear_Nm + 0.0 * delta
    elif model.boundary == "spring":
        output_torque = rbg * (model.spring_stiffness_N_per_m * (q[1] + u_static) + model.spring_damping_Ns_per_m * qd[1])
    else:
        output_torque = rbg * reaction + 0.0 * delta
    output_power = xp.sum(w * output_torque * wg_tot, axis=-1)
    return {
        "mean_input_power_W": input_power,
        "mean_output_power_W": output_power,
        "mean_power_loss_W": input_power - output_power,
        "mean_friction_loss_W": friction_loss,
    }
