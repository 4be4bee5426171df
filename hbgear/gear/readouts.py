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

:func:`order_amplitudes` reads the spectrum at mesh orders of many points at once straight from
their harmonic-balance coefficients (no sampling, no FFT): the order tracking of a curve.
"""

from __future__ import annotations

import numpy as np

__all__ = ["order_amplitudes", "periodic_summary", "SUMMARY_KEYS"]

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


def order_amplitudes(coefficients, nu: int, orders, weights=None, rate_weights=None, base_frequency=None) -> np.ndarray:
    r"""Amplitudes at mesh orders of a linear read-out of many periodic solutions, from their coefficients.

    The read-out is ``x(t) = sum_i w_i q_i(t) + v_i q_i'(t)`` (DTE: ``w = (1, 0, ...)``, ``v = 0``;
    a bearing force ``k y + c y'``: ``w_y = k``, ``v_y = c``). With ``q_i = a_i0 + sum_k a_ik cos(k tau)
    + b_ik sin(k tau)`` on the base frequency ``w = w_m / nu``, base harmonic ``k`` is mesh order
    ``r = k / nu`` and

    ``A_r = |(sum_i w_i a_ik + v_i k w b_ik, sum_i w_i b_ik - v_i k w a_ik)|``, so that
    ``x = x_0 + sum_r A_r cos(r w_m t + phi_r)``.

    An order that is not a multiple of ``1/nu`` has amplitude 0 exactly (the solution repeats
    every ``nu`` mesh periods: its spectrum lies on multiples of ``1/nu``).

    **Arguments:** `coefficients`: ``(P, ndof, 2H+1)`` real coefficients [SI] (basis of
    :mod:`hbgear.engine.fourier`); `nu`; `orders`: mesh orders ``r > 0`` with ``r nu <= H``;
    `weights` ``w`` ``(ndof,)`` (default: coordinate 0, the DTE); `rate_weights` ``v`` ``(ndof,)``
    (default none); `base_frequency` ``w`` [rad/s], scalar or ``(P,)``, needed with `rate_weights`.

    **Returns:** ``(P, len(orders))`` amplitudes in the units of ``x``.

    **Raises:** ``ValueError`` for an order ``<= 0`` or above ``H / nu`` (not resolved by the basis).
    """
    c = np.asarray(coefficients, dtype=float)
    harmonics = (c.shape[-1] - 1) // 2
    orders = np.asarray(orders, dtype=float).ravel()
    base = orders * nu
    k = np.rint(base).astype(int)
    if np.any(orders <= 0) or np.any(base > harmonics + 1e-9):
        raise ValueError(f"mesh orders {orders.tolist()}: each must lie in (0, H/nu] = (0, {harmonics / nu:g}] "
                         f"(H = {harmonics}, nu = {nu})")
    on_grid = np.abs(base - k) <= 1e-9
    w = np.zeros(c.shape[-2]) if weights is None else np.asarray(weights, dtype=float)
    if weights is None:
        w[0] = 1.0
    a = np.einsum("i,pik->pk", w, c[..., 1::2])  # (P, H): cos coefficients of x, rate terms below
    b = np.einsum("i,pik->pk", w, c[..., 2::2])
    if rate_weights is not None:
        if base_frequency is None:
            raise ValueError("rate_weights need the base frequency w_m / nu of every point")
        kw = np.arange(1, harmonics + 1) * np.reshape(np.asarray(base_frequency, dtype=float), (-1, 1))
        v = np.asarray(rate_weights, dtype=float)
        va, vb = np.einsum("i,pik->pk", v, c[..., 1::2]), np.einsum("i,pik->pk", v, c[..., 2::2])
        a, b = a + kw * vb, b - kw * va
    column = np.clip(k - 1, 0, max(harmonics - 1, 0))
    return np.where(on_grid, np.hypot(a[:, column], b[:, column]), 0.0)
