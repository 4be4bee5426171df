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
  ``-<T_fp (Omega_p + theta_p') + T_fg (Omega_g + theta_g') + F_fp x_p' + F_fg x_g'>`` plus the mesh
  power ``<F_mesh delta'>`` plus, on bearings and shafts (MODEL.md section 10), their damper losses
  ``<sum c v^2>`` (``mean_bearing_loss_W``, ``mean_shaft_loss_W``). With shafts the input and output
  speeds are those of the drive and load inertias.

Bearing forces (with bearings): ``k y + c y'`` per gear and direction (the static load included),
their mean, RMS about the mean and peak-to-peak (:data:`BEARING_FORCES`, :func:`summary_keys`).

With a single DTE coordinate (torques) the rigid-body speeds are the nominal ones.

:func:`order_amplitudes` reads the spectrum at mesh orders of many points at once straight from
their harmonic-balance coefficients (no sampling, no FFT): the order tracking of a curve.
"""

from __future__ import annotations

import numpy as np

__all__ = ["order_amplitudes", "periodic_summary", "SUMMARY_KEYS", "BEARING_FORCES", "bearing_coefficients",
           "bearing_keys", "bearing_weights", "summary_keys"]

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

#: The bearing forces of :meth:`~hbgear.gear.model.GearPairModel.bearing_forces`, in output order.
BEARING_FORCES = ("pinion_loa", "pinion_oloa", "gear_loa", "gear_oloa")


def bearing_keys(statistics=("rms", "p2p", "mean")) -> tuple:
    """``bearing_force_<gear>_<direction>_<statistic>_N`` for every bearing force, statistic by statistic."""
    return tuple(f"bearing_force_{name}_{stat}_N" for stat in statistics for name in BEARING_FORCES)


def summary_keys(model) -> tuple:
    """The keys :func:`periodic_summary` returns for `model`: :data:`SUMMARY_KEYS`, and with bearings
    :func:`bearing_keys` and ``mean_bearing_loss_W`` (with shafts also ``mean_shaft_loss_W``)."""
    keys = SUMMARY_KEYS
    if model.bearings is not None:
        keys = keys + bearing_keys() + ("mean_bearing_loss_W",)
    if model.shafts is not None:
        keys = keys + ("mean_shaft_loss_W",)
    return keys


def periodic_summary(model, omega_pinion, s, q, qd, weights, u_static=0.0, reaction=0.0, xp=np,
                     keys=None) -> dict:
    """Scalar read-outs of one steady-state period.

    **Arguments:**

    - `model`: the :class:`~hbgear.gear.model.GearPairModel`; `omega_pinion`: ``Omega_p`` [rad/s].
    - `s`: mesh phase in [0, 1) at the nodes; `q`, `qd`: state at the nodes, shape
      ``(ndof, n)`` [m], [m/s]; `weights`: quadrature weights over the period (sum 1).
    - `u_static`: the spring's static wind-up [m]; `reaction`: ``T_g/R_bg`` [N] (reaction).
    - `keys`: the read-outs wanted (a subset of :func:`summary_keys`, default all of them; only
      what they need is evaluated: the mesh force for the dynamic factor and the mesh power, the
      friction for the powers, the supports for the bearing forces and damper losses).

    Batches: ``q``, ``qd`` of shape ``(ndof, P, n)`` with `omega_pinion`, `u_static`, `reaction`
    of shape ``(P, 1)`` and ``s`` of shape ``(1, n)`` give every read-out with shape ``(P,)``
    (means and extremes are over the last axis).

    **Returns:** a dict with `keys` (µm, W, N, -).
    """
    known = summary_keys(model)
    keys = known if keys is None else tuple(keys)
    unknown = set(keys) - set(known)
    if unknown:
        raise ValueError(f"unknown read-outs {sorted(unknown)}; known for this model: {known}")
    wanted = set(keys)
    w = weights
    delta = q[0]
    mean, rms = _mean_rms(delta, w, xp)
    out = {"dte_mean_um": 1e6 * mean, "dte_rms_um": 1e6 * rms, "dte_p2p_um": 1e6 * _p2p(delta, xp)}
    if {"dynamic_factor", "mean_mesh_power_W"} & wanted:
        mesh = model.mesh_force(s, q, qd, omega_pinion, xp)
        out["dynamic_factor"] = xp.max(mesh, axis=-1) / model.normal_load_N
        out["mean_mesh_power_W"] = xp.sum(w * mesh * qd[0], axis=-1)
    if set(SUMMARY_KEYS[4:8]) & wanted:
        out.update(_powers(model, omega_pinion, s, q, qd, w, u_static, reaction, xp))
    if wanted - set(SUMMARY_KEYS):
        out.update(_support_readouts(model, q, qd, w, xp))
    return {k: out[k] for k in keys}


def _powers(model, omega_pinion, s, q, qd, w, u_static, reaction, xp) -> dict:
    """The mean input, output and lost powers and the friction loss of :func:`periodic_summary`."""
    delta = q[0]
    wp_tot, wg_tot = model.angular_velocities(qd, omega_pinion, nominal=False)
    t_fp, t_fg, f_fp, f_fg = model.friction_actions(s, q, qd, omega_pinion, xp)
    friction_power = t_fp * wp_tot + t_fg * wg_tot
    if model.bearings is not None:
        lay = model.layout
        friction_power = friction_power + f_fp * qd[lay.index("x_p")] + f_fg * qd[lay.index("x_g")]
    friction_loss = -xp.sum(w * friction_power, axis=-1)
    w_in, w_out = (wp_tot, wg_tot) if model.shafts is None else model.body_speeds(qd, omega_pinion)
    input_power = model.torque_pinion_Nm * xp.sum(w * w_in, axis=-1)
    rbg = model.base_radius_gear_m
    if model.boundary == "torques":
        output_torque = model.torque_gear_Nm + 0.0 * delta
    elif model.boundary == "spring":
        output_torque = rbg * (model.spring_stiffness_N_per_m * (q[1] + u_static) + model.spring_damping_Ns_per_m * qd[1])
    else:
        output_torque = rbg * reaction + 0.0 * delta
    output_power = xp.sum(w * output_torque * w_out, axis=-1)
    return {
        "mean_input_power_W": input_power,
        "mean_output_power_W": output_power,
        "mean_power_loss_W": input_power - output_power,
        "mean_friction_loss_W": friction_loss,
    }


def _support_readouts(model, q, qd, w, xp) -> dict:
    """The bearing forces' mean, RMS and peak-to-peak and the supports' damper losses."""
    out = {}
    for name, force in model.bearing_forces(q, qd).items():
        f_mean, f_rms = _mean_rms(force, w, xp)
        out |= {f"bearing_force_{name}_rms_N": f_rms, f"bearing_force_{name}_p2p_N": _p2p(force, xp),
                f"bearing_force_{name}_mean_N": f_mean}
    for group, loss in model.support_losses(qd).items():
        out[f"mean_{group[:-1]}_loss_W"] = xp.sum(w * loss, axis=-1)
    return out


def bearing_weights(model) -> dict:
    """Each bearing force as the linear read-out ``w.q + v.q' + f_0`` of the coordinates:
    name -> ``(w, v, f_0)`` (``w``, ``v`` of shape ``(ndof,)``, ``f_0`` the static load [N]), from
    :meth:`~hbgear.gear.model.GearPairModel.bearing_forces` itself (it is affine in ``q, q'``)."""
    n = model.ndof
    zero = np.zeros((n, 1))
    base = {k: float(np.asarray(v)[0]) for k, v in model.bearing_forces(zero, zero).items()}
    out = {name: (np.zeros(n), np.zeros(n), value) for name, value in base.items()}
    for j in range(n):
        unit = np.zeros((n, 1))
        unit[j] = 1.0
        for name, value in model.bearing_forces(unit, zero).items():
            out[name][0][j] = float(np.asarray(value)[0]) - base[name]
        for name, value in model.bearing_forces(zero, unit).items():
            out[name][1][j] = float(np.asarray(value)[0]) - base[name]
    return out


def bearing_coefficients(model, coefficients, base_frequency) -> dict:
    """Fourier coefficients [N] of every bearing force (:func:`bearing_weights`) of ``P`` solutions:
    `coefficients` ``(P, ndof, 2H+1)`` [m] on the base frequency `base_frequency` ``(P,)`` [rad/s];
    name -> ``(P, 2H+1)`` (empty with rigid bearings)."""
    c = np.asarray(coefficients, dtype=float)
    harmonics = (c.shape[-1] - 1) // 2
    kw = np.arange(1, harmonics + 1) * np.reshape(np.asarray(base_frequency, dtype=float), (-1, 1))  # (P, H)
    rate = np.zeros_like(c)
    rate[..., 1::2], rate[..., 2::2] = kw[:, None] * c[..., 2::2], -kw[:, None] * c[..., 1::2]
    out = {}
    for name, (w, v, f0) in bearing_weights(model).items():
        force = np.einsum("i,pik->pk", w, c) + np.einsum("i,pik->pk", v, rate)
        force[:, 0] += f0
        out[name] = force
    return out


def _mean_rms(x, w, xp):
    """Mean and RMS about the mean over the period's quadrature (last axis)."""
    mean = xp.sum(w * x, axis=-1)
    return mean, xp.sqrt(xp.sum(w * (x - mean[..., None]) ** 2, axis=-1))


def _p2p(x, xp):
    return xp.max(x, axis=-1) - xp.min(x, axis=-1)


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
