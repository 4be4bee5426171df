r"""Single-pair stiffness from the potential-energy method (Yang & Lin 1987; Sainsot et al. 2004).

Each tooth is a non-uniform cantilever on its centreline ``X`` from the base circle to the
contact point (the Yang-Lin / Tian form, valid when the root circle lies inside the base
circle), loaded by the normal force ``F`` at the angle ``alpha_1`` to the perpendicular of the
centreline. At involute pressure angle ``alpha`` the profile point has radius
``r = R_b / cos(alpha)``, half-angle ``psi = alpha_2 - inv(alpha)`` and
``X = r cos(psi)``, half-thickness ``h = r sin(psi)``, with the half tooth angle on the base
circle ``alpha_2 = pi/(2Z) + 2 x tan(phi)/Z + inv(phi)``; at the contact
``alpha_1 = alpha_c - psi_c``. Per tooth, with ``A = 2 h b``, ``I = (2h)^3 b / 12``,
``G = E / (2(1 + nu))``:

    1/k_b = int [(X_c - X) cos(alpha_1) - h_c sin(alpha_1)]^2 / (E I) dX
    1/k_s = int 1.2 cos^2(alpha_1) / (G A) dX
    1/k_a = int sin^2(alpha_1) / (E A) dX
    1/k_f = cos^2(alpha_1)/(E b) [L* (u_f/S_f)^2 + M* (u_f/S_f) + P* (1 + Q* tan^2(alpha_1))]

(the integrals from the base circle to the contact; ``k_f`` the fillet-foundation (gear body)
term of Sainsot, Velex & Duverger 2004 with ``u_f = X_c - h_c tan(alpha_1) - r_f`` the distance
from the load line's crossing of the centreline to the root circle, ``S_f = 2 r_f theta_f``
and the fitted ``L*, M*, P*, Q*`` of ``h_f = r_f / r_int`` and ``theta_f``). The pair adds the
Hertzian term ``1/k_h = 4 (1 - nu^2) / (pi E b)`` (Yang & Lin) in series:
``1/k = 1/k_h + sum over both teeth of (1/k_b + 1/k_s + 1/k_a + 1/k_f)``.

``theta_f``, the half tooth angle at the root circle, follows from generation by the basic
rack (dedendum ``h_fP``, tip radius ``rho_fP``): the rack's tip flat of half-width
``e = pi m/4 - h_fP tan(phi) - rho_fP (1 - sin(phi))/cos(phi)`` rolls on the pitch circle
``r`` and imprints the root arc of half-angle ``e/r``, so ``theta_f = pi/Z - e/r`` (a profile
shift moves the root circle, ``r_f = r - h_fP + x m``, not this angle).
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry import GearPair, involute
from .stiffness import TablePairStiffness

__all__ = ["SAINSOT_COEFFICIENTS", "potential_energy_pair_stiffness", "tooth_compliances"]

#: ``(A, B, C, D, E, F)`` of ``X* = A/theta_f^2 + B h_f^2 + C h_f/theta_f + D/theta_f + E h_f + F``
#: for ``L*, M*, P*, Q*`` (Sainsot, Velex & Duverger 2004, fitted for 1.4 <= h_f <= 7,
#: 0.01 <= theta_f <= 0.12 rad).
SAINSOT_COEFFICIENTS = {
    "L": (-5.574e-5, -1.9986e-3, -2.3015e-4, 4.7702e-3, 0.0271, 6.8045),
    "M": (60.111e-5, 28.100e-3, -83.431e-4, -9.9256e-3, 0.1624, 0.9086),
    "P": (-50.952e-5, 185.50e-3, 0.0538e-4, 53.300e-3, 0.2895, 0.9236),
    "Q": (-6.2042e-5, 9.0889e-3, -4.0964e-4, 7.8297e-3, -0.1472, 0.6904),
}

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(64)


def _profile(alpha, base_radius, half_angle):
    """``(X, h, dX/dalpha)`` of the involute at pressure angle(s) `alpha`."""
    r = base_radius / np.cos(alpha)
    psi = half_angle - (np.tan(alpha) - alpha)
    dr = base_radius * np.sin(alpha) / np.cos(alpha) ** 2
    dpsi = -np.tan(alpha) ** 2
    return r * np.cos(psi), r * np.sin(psi), dr * np.cos(psi) - r * np.sin(psi) * dpsi


def tooth_compliances(teeth: int, module_m: float, pressure_angle_rad: float, profile_shift: float,
                      contact_pressure_angle, face_width_m: float, youngs_modulus_Pa: float, poisson_ratio: float,
                      bore_radius_m: float, rack_dedendum_coefficient: float = 1.25,
                      rack_tip_radius_coefficient: float = 0.38) -> dict[str, np.ndarray]:
    """Bending, shear, axial and fillet-foundation compliances of one tooth [m/N].

    **Arguments:** the gear (`teeth`, `module_m`, `pressure_angle_rad`, `profile_shift`), the
    contact's involute pressure angle(s) `contact_pressure_angle` [rad], `face_width_m`, the
    material (`youngs_modulus_Pa`, `poisson_ratio`), the blank's `bore_radius_m` (``r_int``) and
    the basic rack (``h_fP/m``, ``rho_fP/m``; ISO 53 profile A by default).

    **Returns:** ``{"bending", "shear", "axial", "fillet"}``, each the shape of
    `contact_pressure_angle`.
    """
    phi, z, m, b, e_mod = pressure_angle_rad, teeth, module_m, face_width_m, youngs_modulus_Pa
    base_radius = m * z / 2 * math.cos(phi)
    half_angle = math.pi / (2 * z) + 2 * profile_shift * math.tan(phi) / z + involute(phi)
    alpha_c = np.atleast_1d(np.asarray(contact_pressure_angle, dtype=float))
    x_c, h_c, _ = _profile(alpha_c, base_radius, half_angle)
    alpha_1 = alpha_c - (half_angle - (np.tan(alpha_c) - alpha_c))
    # Gauss-Legendre in alpha from the base circle (alpha = 0) to the contact
    alpha = 0.5 * alpha_c[:, None] * (_NODES[None] + 1.0)
    weight = 0.5 * alpha_c[:, None] * _WEIGHTS[None]
    x, h, dx = _profile(alpha, base_radius, half_angle)
    area, inertia = 2 * h * b, (2 * h) ** 3 * b / 12
    cos1, sin1 = np.cos(alpha_1)[:, None], np.sin(alpha_1)[:, None]
    shear_modulus = e_mod / (2 * (1 + poisson_ratio))
    arm = (x_c[:, None] - x) * cos1 - h_c[:, None] * sin1
    bending = np.sum(weight * arm**2 / (e_mod * inertia) * dx, axis=1)
    shear = np.sum(weight * 1.2 * cos1**2 / (shear_modulus * area) * dx, axis=1)
    axial = np.sum(weight * sin1**2 / (e_mod * area) * dx, axis=1)
    # fillet foundation (Sainsot et al. 2004)
    root_radius = m * (z / 2 - rack_dedendum_coefficient + profile_shift)
    flat = (math.pi * m / 4 - rack_dedendum_coefficient * m * math.tan(phi)
            - rack_tip_radius_coefficient * m * (1 - math.sin(phi)) / math.cos(phi))
    theta_f = math.pi / z - flat / (m * z / 2)
    h_f = root_radius / bore_radius_m
    fit = {name: a / theta_f**2 + bb * h_f**2 + c * h_f / theta_f + d / theta_f + e * h_f + f
           for name, (a, bb, c, d, e, f) in SAINSOT_COEFFICIENTS.items()}
    ratio = (x_c - h_c * np.tan(alpha_1) - root_radius) / (2 * root_radius * theta_f)
    fillet = np.cos(alpha_1) ** 2 / (e_mod * b) * (fit["L"] * ratio**2 + fit["M"] * ratio
                                                  + fit["P"] * (1 + fit["Q"] * np.tan(alpha_1) ** 2))
    shape = np.shape(contact_pressure_angle)
    return {name: np.reshape(value, shape) for name, value in
            (("bending", bending), ("shear", shear), ("axial", axial), ("fillet", fillet))}


def potential_energy_pair_stiffness(pair: GearPair, face_width_m: float, youngs_modulus_Pa: float,
                                    poisson_ratio: float, bore_radius_m: tuple[float, float], samples: int = 101,
                                    **rack) -> TablePairStiffness:
    """``k_pair(xi)`` of `pair` by the potential-energy method, sampled along the path.

    The pinion contact at ``xi_p`` (from ``T_1``) has ``tan(alpha_c,p) = xi_p / R_bp``, the gear's
    ``tan(alpha_c,g) = (L - xi_p) / R_bg``. `bore_radius_m` is ``(r_int,p, r_int,g)``; `rack`
    goes to :func:`tooth_compliances`. The result interpolates `samples` equally spaced points
    piecewise linearly.
    """
    xi = np.linspace(0.0, pair.contact_end_m - pair.contact_start_m, samples)
    xi_p = pair.contact_start_m + xi
    compliance = 4 * (1 - poisson_ratio**2) / (math.pi * youngs_modulus_Pa * face_width_m)
    for teeth, shift, base_radius, roll, bore in (
        (pair.teeth_pinion, pair.profile_shift_pinion, pair.base_radius_pinion_m, xi_p, bore_radius_m[0]),
        (pair.teeth_gear, pair.profile_shift_gear, pair.base_radius_gear_m, pair.line_of_action_m - xi_p,
         bore_radius_m[1]),
    ):
        parts = tooth_compliances(teeth, pair.module_m, pair.pressure_angle_rad, shift, np.arctan(roll / base_radius),
                                  face_width_m, youngs_modulus_Pa, poisson_ratio, bore, **rack)
        compliance = compliance + sum(parts.values())
    return TablePairStiffness(tuple(xi.tolist()), tuple((1.0 / compliance).tolist()))
