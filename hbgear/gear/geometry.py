"""Spur-gear geometry and mesh kinematics along the line of action (MODEL.md section 1).

Positions along the line of action are measured from the pinion's base-circle tangency point
T1. Tooth pair ``k`` (``k = 0`` the pair that entered at the start of the current mesh
period, ``k = 1`` the pair that entered one period earlier, ...) sits at

    xi_p,k(s) = x_A + p_b (s + k),     xi_g,k = L - xi_p,k,

where ``s = (t mod T_m) / T_m`` is the mesh phase in [0, 1). Everything here is a function of
the mesh phase only; speed enters through the mesh period ``T_m = 2 pi / (Z_p Omega_p)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import ConfigError

__all__ = ["GearPair", "involute", "inverse_involute"]


def involute(angle_rad: float) -> float:
    """``inv(a) = tan(a) - a``."""
    return math.tan(angle_rad) - angle_rad


def inverse_involute(value: float) -> float:
    """The angle ``a`` in [0, pi/2) with ``tan(a) - a = value`` (``value >= 0``).

    Newton's method on the convex, increasing ``inv`` from ``a0 = (3 value)^(1/3)`` (the
    leading term of ``inv(a) = a^3/3 + ...``), which overshoots and then decreases
    monotonically to the root; it stops when a step no longer changes ``a``.
    """
    if value == 0.0:
        return 0.0
    a = (3.0 * value) ** (1.0 / 3.0)
    for _ in range(60):
        step = (involute(a) - value) / math.tan(a) ** 2
        if not math.isfinite(step) or a - step == a:
            break
        a -= step
    return a


@dataclass(frozen=True)
class GearPair:
    """External spur-gear pair with a common addendum coefficient and optional profile shift.

    **Arguments:**

    - `teeth_pinion`, `teeth_gear`: tooth counts ``Z_p``, ``Z_g`` [-].
    - `module_m`: module ``m`` [m].
    - `pressure_angle_rad`: pressure angle ``phi`` of the basic rack [rad].
    - `addendum_coefficient`: ``h_a`` [-]; addendum radius ``r_a = r + (h_a + x) m``.
    - `profile_shift_pinion`, `profile_shift_gear`: profile shift coefficients ``x_1``, ``x_2``
      [-] (default 0).
    - `working_center_distance_m`: an imposed centre distance ``a_w`` [m]; ``None`` (default)
      means the zero-backlash distance of the shifted pair, from
      ``inv(phi_w) = inv(phi) + 2 tan(phi) (x_1 + x_2) / (Z_p + Z_g)``.
    - `tip_shortening`: shorten both tips by ``k m``, ``k = x_1 + x_2 - y``,
      ``y = (a_w - a) / m`` (keeps the basic-rack bottom clearance when ``x_1 + x_2 > y``);
      default ``False``: ``r_a = r + (h_a + x) m``.

    With no shift and no imposed centre distance every quantity is computed exactly as for the
    unshifted pair (``phi_w = phi``, ``a_w = r_p + r_g``), so results are bit-identical.
    """

    teeth_pinion: int
    teeth_gear: int
    module_m: float
    pressure_angle_rad: float
    addendum_coefficient: float = 1.0
    profile_shift_pinion: float = 0.0
    profile_shift_gear: float = 0.0
    working_center_distance_m: float | None = None
    tip_shortening: bool = False

    # -- radii [m] ------------------------------------------------------------------------
    @property
    def pitch_radius_pinion_m(self) -> float:
        return self.module_m * self.teeth_pinion / 2

    @property
    def pitch_radius_gear_m(self) -> float:
        return self.module_m * self.teeth_gear / 2

    @property
    def base_radius_pinion_m(self) -> float:
        return self.pitch_radius_pinion_m * math.cos(self.pressure_angle_rad)

    @property
    def base_radius_gear_m(self) -> float:
        return self.pitch_radius_gear_m * math.cos(self.pressure_angle_rad)

    @property
    def _unshifted(self) -> bool:
        return (
            self.profile_shift_pinion == 0.0
            and self.profile_shift_gear == 0.0
            and self.working_center_distance_m is None
        )

    @property
    def reference_center_distance_m(self) -> float:
        """``a = (r_p + r_g)``: the centre distance of the unshifted pair."""
        return self.pitch_radius_pinion_m + self.pitch_radius_gear_m

    @property
    def working_pressure_angle_rad(self) -> float:
        """``phi_w``: ``cos(phi_w) = a cos(phi) / a_w`` for an imposed ``a_w``, else from
        ``inv(phi_w) = inv(phi) + 2 tan(phi) (x_1 + x_2) / (Z_p + Z_g)`` (zero backlash)."""
        phi = self.pressure_angle_rad
        if self._unshifted:
            return phi
        if self.working_center_distance_m is not None:
            return math.acos(self.reference_center_distance_m * math.cos(phi) / self.working_center_distance_m)
        shift = self.profile_shift_pinion + self.profile_shift_gear
        return inverse_involute(involute(phi) + 2 * math.tan(phi) * shift / (self.teeth_pinion + self.teeth_gear))

    @property
    def center_distance_m(self) -> float:
        """Working centre distance ``a_w = a cos(phi) / cos(phi_w)`` (``a`` when unshifted)."""
        if self._unshifted:
            return self.reference_center_distance_m
        if self.working_center_distance_m is not None:
            return self.working_center_distance_m
        return self.reference_center_distance_m * math.cos(self.pressure_angle_rad) / math.cos(
            self.working_pressure_angle_rad
        )

    @property
    def center_distance_modification(self) -> float:
        """``y = (a_w - a) / m`` [-]."""
        return (self.center_distance_m - self.reference_center_distance_m) / self.module_m

    @property
    def tip_shortening_coefficient(self) -> float:
        """``k = x_1 + x_2 - y`` when `tip_shortening`, else 0 [-]."""
        if not self.tip_shortening:
            return 0.0
        return self.profile_shift_pinion + self.profile_shift_gear - self.center_distance_modification

    @property
    def tip_radius_pinion_m(self) -> float:
        """``r_ap = r_p + (h_a + x_1 - k) m`` (exactly ``r_p + h_a m`` when ``x_1 = k = 0``)."""
        addendum = self.addendum_coefficient + self.profile_shift_pinion - self.tip_shortening_coefficient
        return self.pitch_radius_pinion_m + addendum * self.module_m

    @property
    def tip_radius_gear_m(self) -> float:
        """``r_ag = r_g + (h_a + x_2 - k) m``."""
        addendum = self.addendum_coefficient + self.profile_shift_gear - self.tip_shortening_coefficient
        return self.pitch_radius_gear_m + addendum * self.module_m

    @property
    def gear_ratio(self) -> float:
        """``Z_g / Z_p`` [-]."""
        return self.teeth_gear / self.teeth_pinion

    # -- line of action [m] ---------------------------------------------------------------
    @property
    def line_of_action_m(self) -> float:
        """``L = a_w sin(phi_w)``, between the two base-circle tangency points."""
        return self.center_distance_m * math.sin(self.working_pressure_angle_rad)

    @property
    def base_pitch_m(self) -> float:
        """``p_b = 2 pi R_bp / Z_p``."""
        return 2 * math.pi * self.base_radius_pinion_m / self.teeth_pinion

    @property
    def contact_start_m(self) -> float:
        """``x_A = L - sqrt(r_ag^2 - R_bg^2)``: where a pair enters contact."""
        rag = self.tip_radius_gear_m
        return self.line_of_action_m - math.sqrt(rag**2 - self.base_radius_gear_m**2)

    @property
    def contact_end_m(self) -> float:
        """``x_E = sqrt(r_ap^2 - R_bp^2)``: where a pair leaves contact."""
        rap = self.tip_radius_pinion_m
        return math.sqrt(rap**2 - self.base_radius_pinion_m**2)

    @property
    def pitch_point_m(self) -> float:
        """``x_P = R_bp tan(phi_w)``: zero nominal sliding (the working pitch point)."""
        return self.base_radius_pinion_m * math.tan(self.working_pressure_angle_rad)

    @property
    def contact_ratio(self) -> float:
        """Profile contact ratio ``Gamma = (x_E - x_A) / p_b``."""
        return (self.contact_end_m - self.contact_start_m) / self.base_pitch_m

    # -- instants within a mesh period (fractions of T_m) -----------------------------------
    @property
    def double_contact_fraction(self) -> float:
        """``t_a / T_m = Gamma - 1``: two pairs in contact for ``0 <= s < t_a/T_m``."""
        return self.contact_ratio - 1.0

    @property
    def pitch_crossing_fraction(self) -> float:
        """``t_b / T_m = (x_P - x_A) / p_b``: a pair's pitch crossing after its entry."""
        return (self.pitch_point_m - self.contact_start_m) / self.base_pitch_m

    @property
    def pair_slots(self) -> int:
        """Number of pair slots ``ceil(Gamma)`` that can be in contact at once."""
        return math.ceil(self.contact_ratio)

    def phase_breakpoints(self) -> tuple[float, ...]:
        """Sorted mesh phases in [0, 1) where contact or nominal sliding changes.

        Pair entry (0), pair exit (``Gamma - 1``) and the pitch crossing of every slot that
        is in contact when it happens.
        """
        points = {0.0, self.double_contact_fraction}
        for slot in range(self.pair_slots):
            s = self.pitch_crossing_fraction - slot
            if 0.0 <= s < 1.0 and s + slot <= self.contact_ratio:
                points.add(s)
        return tuple(sorted(points))

    # -- validation and construction -------------------------------------------------------
    def check(self, key: str = "gear.addendum_coefficient") -> GearPair:
        """Raise :class:`ConfigError` unless the geometry is valid and ``1 < Gamma < 2``."""
        rag, rap = self.tip_radius_gear_m, self.tip_radius_pinion_m
        if rag <= self.base_radius_gear_m or rap <= self.base_radius_pinion_m:
            raise ConfigError(key, self.addendum_coefficient, "an addendum beyond the base circles")
        gamma = self.contact_ratio
        if not (1.0 < gamma < 2.0) or self.contact_start_m < 0 or self.contact_end_m > self.line_of_action_m:
            raise ConfigError(
                key,
                self.addendum_coefficient,
                f"a value giving a contact ratio in (1, 2) inside the line of action (gives {gamma:.4f})",
            )
        return self

    @classmethod
    def with_contact_ratio(
        cls,
        teeth_pinion: int,
        teeth_gear: int,
        module_m: float,
        pressure_angle_rad: float,
        contact_ratio: float,
        key: str = "gear.contact_ratio",
    ) -> GearPair:
        """Solve the common addendum coefficient ``h_a`` for a target contact ratio.

        ``Gamma(h_a)`` increases monotonically, so bisection on ``h_a`` in (0, 2] is robust.
        """
        if not (1.0 < contact_ratio < 2.0):
            raise ConfigError(key, contact_ratio, "a contact ratio strictly between 1 and 2")

        def gamma(ha: float) -> float:
            return cls(teeth_pinion, teeth_gear, module_m, pressure_angle_rad, ha).contact_ratio

        lo, hi = 1e-6, 2.0
        if not (gamma(lo) < contact_ratio < gamma(hi)):
            raise ConfigError(
                key,
                contact_ratio,
                f"a contact ratio this tooth pair can reach ({gamma(lo):.3f} .. {gamma(hi):.3f})",
            )
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if gamma(mid) < contact_ratio:
                lo = mid
            else:
                hi = mid
            if hi - lo < 1e-15:
                break
        return cls(teeth_pinion, teeth_gear, module_m, pressure_angle_rad, 0.5 * (lo + hi)).check(key)
