r"""Tooth stiffness after ISO 6336-1 method B, spread along the path of contact.

ISO 6336-1 (section 9, "tooth stiffness parameters c' and c_gamma", method B) gives, per unit
face width [N/(mm um)]:

- the theoretical single stiffness ``c'_th = 1/q'`` with the flexibility polynomial
  ``q' = C1 + C2/z_n1 + C3/z_n2 + C4 x1 + C5 x1/z_n1 + C6 x2 + C7 x2/z_n2 + C8 x1^2 + C9 x2^2``
  [mm um/N], ``z_n = z / (cos^2(beta_b) cos(beta))`` (``z_n = z`` for spur gears);
- the single stiffness (the maximum stiffness of one tooth pair)
  ``c' = c'_th C_M C_R C_B cos(beta) (E/E_st) f_w`` with ``C_M = 0.8``, the gear-blank factor
  ``C_R`` (1 for solid blanks), the basic-rack factor
  ``C_B = mean_i [1 + 0.5 (1.2 - h_fP,i/m)] [1 - 0.02 (20 deg - alpha_P)]`` (1 for
  ``h_fP = 1.2 m``, ``alpha_P = 20 deg``), the modulus ratio ``E/E_st``,
  ``E = 2 E1 E2/(E1 + E2)``, ``E_st = 206 GPa`` (the coefficients are for steel on steel),
  and the low line-load factor ``f_w = (w/100)^0.25`` for a line load ``w = F_t K_A / b`` below
  100 N/mm (1 above);
- the mesh stiffness ``c_gamma_alpha = c' (0.75 eps_alpha + 0.25)`` (mean over the mesh
  period of the stiffness of all pairs in contact) and ``c_gamma_beta = 0.85 c_gamma_alpha``.

The standard gives these two numbers, not a stiffness curve. :class:`Iso6336PairStiffness`
spreads them over the path with a symmetric parabola whose maximum is ``c' b`` and whose
mesh-period mean of ``sum_j k_pair(xi_j)`` is ``c_gamma_alpha b`` (see its docstring and
docs/tooth_contact.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..geometry import GearPair

__all__ = [
    "ISO6336_COEFFICIENTS",
    "Iso6336PairStiffness",
    "Iso6336Stiffness",
    "iso6336_stiffness",
    "parabola_curvature",
]

#: ``C1 .. C9`` of the flexibility polynomial ``q'`` (ISO 6336-1 method B) [mm um/N].
ISO6336_COEFFICIENTS = (0.04723, 0.15551, 0.25791, -0.00635, -0.11654, -0.00193, -0.24188, 0.00529, 0.00182)

#: ``E_st`` [Pa], the modulus the coefficients belong to (steel on steel).
STEEL_MODULUS_PA = 206e9

#: ``C_M``, the correction from theoretical to measured stiffness of solid gears.
CORRECTION_FACTOR = 0.8


class Iso6336Stiffness(NamedTuple):
    """Method-B stiffness numbers; stiffnesses per unit face width [N/(mm um)]."""

    virtual_teeth: tuple[float, float]  #: ``(z_n1, z_n2)``
    q_prime_mm_um_per_N: float  #: ``q'``
    c_th_N_per_mm_um: float  #: ``c'_th = 1/q'``
    basic_rack_factor: float  #: ``C_B``
    line_load_factor: float  #: ``f_w``
    c_prime_N_per_mm_um: float  #: ``c'``
    c_gamma_alpha_N_per_mm_um: float  #: ``c_gamma_alpha``
    c_gamma_beta_N_per_mm_um: float  #: ``c_gamma_beta = 0.85 c_gamma_alpha``


def iso6336_stiffness(
    teeth: tuple[int, int],
    profile_shift: tuple[float, float],
    contact_ratio: float,
    *,
    pressure_angle_rad: float = math.radians(20.0),
    helix_angle_rad: float = 0.0,
    rack_dedendum_coefficient: tuple[float, float] = (1.2, 1.2),
    blank_factor: float = 1.0,
    youngs_modulus_Pa: tuple[float, float] = (STEEL_MODULUS_PA, STEEL_MODULUS_PA),
    line_load_N_per_mm: float | None = None,
) -> Iso6336Stiffness:
    """ISO 6336-1 method B single and mesh stiffness (formulas in the module docstring).

    **Arguments:**

    - `teeth`: ``(z1, z2)``; `profile_shift`: ``(x1, x2)`` [-].
    - `contact_ratio`: transverse contact ratio ``eps_alpha`` [-].
    - `pressure_angle_rad`: normal pressure angle of the basic rack ``alpha_P`` [rad].
    - `helix_angle_rad`: ``beta`` [rad] (0 for spur gears).
    - `rack_dedendum_coefficient`: ``h_fP/m`` of each gear's basic rack [-] (1.25 for ISO 53
      profile A, giving ``C_B = 0.975``).
    - `blank_factor`: ``C_R`` [-]. `youngs_modulus_Pa`: ``(E1, E2)`` [Pa].
    - `line_load_N_per_mm`: ``w = F_t K_A / b`` [N/mm]; ``None`` means at least 100 N/mm.

    **Returns:** :class:`Iso6336Stiffness`.
    """
    cos_beta = math.cos(helix_angle_rad)
    sin_base_helix = math.sin(helix_angle_rad) * math.cos(pressure_angle_rad)
    zn1, zn2 = (z / ((1.0 - sin_base_helix**2) * cos_beta) for z in teeth)
    x1, x2 = profile_shift
    c = ISO6336_COEFFICIENTS
    q = (c[0] + c[1] / zn1 + c[2] / zn2 + c[3] * x1 + c[4] * x1 / zn1 + c[5] * x2 + c[6] * x2 / zn2
         + c[7] * x1**2 + c[8] * x2**2)
    angle_deg = math.degrees(pressure_angle_rad)
    c_b = sum((1.0 + 0.5 * (1.2 - h)) * (1.0 - 0.02 * (20.0 - angle_deg)) for h in rack_dedendum_coefficient) / 2
    e1, e2 = youngs_modulus_Pa
    modulus_ratio = 2 * e1 * e2 / (e1 + e2) / STEEL_MODULUS_PA
    f_w = 1.0 if line_load_N_per_mm is None or line_load_N_per_mm >= 100.0 else (line_load_N_per_mm / 100.0) ** 0.25
    c_prime = CORRECTION_FACTOR * blank_factor * c_b * cos_beta * modulus_ratio * f_w / q
    c_gamma_alpha = c_prime * (0.75 * contact_ratio + 0.25)
    return Iso6336Stiffness((zn1, zn2), q, 1.0 / q, c_b, f_w, c_prime, c_gamma_alpha, 0.85 * c_gamma_alpha)


def parabola_curvature(contact_ratio: float) -> float:
    r"""``a = 0.75 (eps - 1)/eps``: the drop of the parabola at the ends of the path.

    With ``k(u) = k_max [1 - a (2u - 1)^2]``, ``u = xi / (eps p_b)``, a pair sweeps the whole
    path once per ``eps`` mesh periods, so the mesh-period mean of ``sum_j k(xi_j)`` is
    ``(1/p_b) int_0^{eps p_b} k dxi = eps k_max (1 - a/3)``; setting it to
    ``k_max (0.75 eps + 0.25)`` gives ``a``.
    """
    return 0.75 * (contact_ratio - 1.0) / contact_ratio


@dataclass(frozen=True)
class Iso6336PairStiffness:
    r"""Single-pair stiffness shaped as a symmetric parabola along the path of contact.

    ``k_pair(xi) = k_max [1 - a (2u - 1)^2]``, ``u = clip(xi / L, 0, 1)``, ``L = x_E - x_A``,
    ``a`` from :func:`parabola_curvature`: the maximum, mid-path, is ``k_max = c' b`` and the
    mesh-period mean of the summed stiffness is ``c_gamma_alpha b`` exactly (for
    ``eps = 1.5`` the ends are at ``0.75 k_max``).

    **Arguments:** `peak_N_per_m`: ``c' b`` [N/m]; `path_length_m`: ``L`` [m];
    `contact_ratio`: ``eps_alpha = L / p_b`` [-].
    """

    peak_N_per_m: float
    path_length_m: float
    contact_ratio: float

    def stiffness(self, xi, xp=np):
        """``k_pair(xi)`` [N/m], the shape of `xi`."""
        u = xp.clip(xp.asarray(xi) / self.path_length_m, 0.0, 1.0)
        return self.peak_N_per_m * (1.0 - parabola_curvature(self.contact_ratio) * (2.0 * u - 1.0) ** 2)

    @classmethod
    def from_geometry(cls, pair: GearPair, face_width_m: float, **options) -> tuple[Iso6336PairStiffness,
                                                                                     Iso6336Stiffness]:
        """The ISO numbers of `pair` (spur, its own ``z``, ``x`` and ``eps_alpha``) and the shape.

        `options` go to :func:`iso6336_stiffness` (rack, blank factor, moduli, line load).

        **Returns:** ``(shape, numbers)``; ``shape.peak_N_per_m = c' b`` with ``b`` in mm and
        ``c'`` in N/(mm um), i.e. ``c' [N/(mm um)] b [mm] 1e6`` [N/m].
        """
        numbers = iso6336_stiffness(
            (pair.teeth_pinion, pair.teeth_gear),
            (pair.profile_shift_pinion, pair.profile_shift_gear),
            pair.contact_ratio,
            pressure_angle_rad=pair.pressure_angle_rad,
            **options,
        )
        peak = numbers.c_prime_N_per_mm_um * (face_width_m * 1e3) * 1e6
        shape = cls(peak, pair.contact_end_m - pair.contact_start_m, pair.contact_ratio)
        return shape, numbers
