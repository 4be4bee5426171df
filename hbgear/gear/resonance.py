r"""The main resonance speed of the pair and its speed ranges after ISO 6336-1 (method B of K_v).

ISO 6336-1:2006, clause 6 ("internal dynamic factor K_v"), method B, 6.5.3, gives (units of the
standard):

- the resonance running speed of the pinion, Eq. (6),
  ``n_E1 = 30000 / (pi z_1) sqrt(c_gamma_alpha / m_red)`` [min^-1], with the mesh stiffness
  ``c_gamma_alpha`` [N/(mm um)] (the mean over the mesh period of the stiffness of all pairs in
  contact, per unit face width) and the reduced mass of the pair per unit face width ``m_red``
  [kg/mm]; that is ``n_E1 = 60 w_E / (2 pi z_1)``, ``w_E = sqrt(c_gamma_alpha b / (m_red b))``:
  the pinion speed whose mesh frequency is the natural frequency of the mesh mode;
- Eq. (7), ``m_red = m_1* m_2* / (m_1* + m_2*)``, with ``m_i* = J_i / (b r_bi^2)`` the masses of
  the two gears reduced to the line of action per unit face width (Eq. (30), 6.5.9, is this for
  solid disks of diameter ``d_m = (d_a + d_f)/2`` and density ``rho``:
  ``m_red = (pi/8) (d_m1/d_b1)^2 d_m1^2 / (1/rho_1 + 1/(rho_2 u^2))``); so ``m_red b = m_e``, the
  model's equivalent mass ``1/(R_bp^2/J_p + R_bg^2/J_g)``;
- the resonance ratio, Eq. (9), ``N = n_1 / n_E1``, and the ranges: subcritical ``N <= N_S``,
  main resonance ``N_S < N <= 1.15``, intermediate ``1.15 < N < 1.5``, supercritical
  ``N >= 1.5``, with ``N_S = 0.5 + 0.35 sqrt(F_t K_A / (100 b))`` for a line load
  ``F_t K_A / b < 100 N/mm`` (Eq. (11)) and ``N_S = 0.85`` otherwise (Eq. (12)).

(Checked against the standard's equations as implemented in the public ISO 6336 calculator
gfsReboucas/Drivetrain-python, ``ISO_6336.py`` and ``notes/internal_dynamic_factor.ipynb``.)

Here ``c_gamma_alpha b = k_mean``, the model's mean mesh stiffness (rectangular model:
``k_max (Gamma - 1) + k_min (2 - Gamma)``); ``F_t = T_p / r_w1`` with the operating pitch radius
``r_w1 = sqrt(R_bp^2 + x_P^2)`` (the standard takes the reference circle; the two differ only for
profile-shifted pairs at a modified centre distance); ``K_A = 1`` unless given (the model's
torque is the load); ``b`` the face width.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["ResonanceRanges", "iso6336_resonance", "MAIN_RESONANCE_UPPER", "SUPERCRITICAL_LOWER"]

#: Upper end of the main resonance range, ``N <= 1.15`` (ISO 6336-1).
MAIN_RESONANCE_UPPER = 1.15
#: Lower end of the supercritical range, ``N >= 1.5`` (ISO 6336-1).
SUPERCRITICAL_LOWER = 1.5


class ResonanceRanges(NamedTuple):
    """ISO 6336-1 method-B resonance numbers of a pair (module docstring).

    Speeds are pinion speeds [rpm]; ranges are ``(from, to)`` pairs.
    """

    n_E1_rpm: float  #: resonance running speed of the pinion ``n_E1``
    c_gamma_alpha_N_per_mm_um: float  #: mesh stiffness per unit face width ``c_gamma_alpha = k_mean / b``
    m_red_kg_per_mm: float  #: reduced mass per unit face width ``m_red = m_e / b``
    line_load_N_per_mm: float  #: ``F_t K_A / b``
    N_S: float  #: lower limit of the main resonance range (resonance ratio)
    subcritical_rpm: tuple  #: ``(0, N_S n_E1)``
    main_resonance_rpm: tuple  #: ``(N_S n_E1, 1.15 n_E1)``
    intermediate_rpm: tuple  #: ``(1.15 n_E1, 1.5 n_E1)``
    supercritical_rpm: tuple  #: ``(1.5 n_E1, inf)``

    def ratio(self, speed_rpm):
        """The resonance ratio ``N = n_1 / n_E1`` (Eq. (9))."""
        return speed_rpm / self.n_E1_rpm

    def as_dict(self) -> dict:
        """The numbers as a JSON-ready dict (the ``frc.json`` record)."""
        return self._asdict() | {"source": "ISO 6336-1:2006 method B: Eq. (6) n_E1, (7) m_red, (9) N, (11)-(12) N_S; "
                                           "m_red b = m_e, c_gamma_alpha b = k_mean, K_A = 1, F_t = T_p / r_w1"}


def iso6336_resonance(model, application_factor: float = 1.0) -> ResonanceRanges:
    """``n_E1``, ``N_S`` and the four speed ranges of ISO 6336-1 for a gear-pair model (module docstring).

    **Arguments:** `model`: a :class:`~hbgear.gear.model.GearPairModel`; `application_factor`:
    ``K_A`` [-] in the line load that sets ``N_S``.

    **Returns:** a :class:`ResonanceRanges`.
    """
    width_mm = 1e3 * float(model.face_width_m)
    c_gamma_alpha = 1e-6 * float(model.k_mean_N_per_m) / width_mm  # N/m -> N/um, per mm of face
    m_red = float(model.mass_equivalent_kg) / width_mm
    n_e1 = 30000.0 / (math.pi * float(model.teeth_pinion)) * math.sqrt(c_gamma_alpha / m_red)
    rbp = float(model.base_radius_pinion_m)
    operating_pitch_radius = math.hypot(rbp, float(model.pitch_point_m))
    line_load = float(model.torque_pinion_Nm) / operating_pitch_radius * application_factor / width_mm
    n_s = 0.85 if line_load >= 100.0 else 0.5 + 0.35 * math.sqrt(line_load / 100.0)
    return ResonanceRanges(
        n_E1_rpm=n_e1, c_gamma_alpha_N_per_mm_um=c_gamma_alpha, m_red_kg_per_mm=m_red, line_load_N_per_mm=line_load,
        N_S=n_s, subcritical_rpm=(0.0, n_s * n_e1), main_resonance_rpm=(n_s * n_e1, MAIN_RESONANCE_UPPER * n_e1),
        intermediate_rpm=(MAIN_RESONANCE_UPPER * n_e1, SUPERCRITICAL_LOWER * n_e1),
        supercritical_rpm=(SUPERCRITICAL_LOWER * n_e1, math.inf))
