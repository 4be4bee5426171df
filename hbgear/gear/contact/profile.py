r"""Profile modifications measured along the line of action (MODEL.md section 9).

A deviation ``e`` is positive where material is removed; a pair with deviation ``e_j`` closes
only once the transmission error exceeds it. Each flank (pinion, gear) has tip and root relief
of amount ``C`` and length ``L`` along the line of action, linear or parabolic:

    e(xi) = C_tip  f((xi - (xi_tip - L_tip)) / L_tip)    for xi > xi_tip - L_tip
          + C_root f(((xi_root + L_root) - xi) / L_root) for xi < xi_root + L_root,

``f(u) = u`` (linear) or ``u^2`` (parabolic), where ``xi`` is the flank's own roll distance from
its base-circle tangency point and ``xi_root``/``xi_tip`` the ends of its active profile. On
the line of action, measured from ``T_1``: the pinion tip is at ``x_E`` (its relief grows to
``C`` at the end of contact), the gear tip at ``x_A`` (growing towards the start of contact);
the pinion root meets the gear tip at ``x_A`` and the gear root meets the pinion tip at ``x_E``.
The composite deviation of a pair at ``xi_p`` is ``e = e_p(xi_p) + e_g(L - xi_p)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ..geometry import GearPair

__all__ = ["SHAPES", "FlankRelief", "ProfileModification", "profile_modification"]

SHAPES = ("linear", "parabolic")


@dataclass(frozen=True)
class FlankRelief:
    """Tip and root relief of one flank, SI.

    **Arguments:** `tip_relief_m`, `tip_length_m`, `root_relief_m`, `root_length_m` [m]
    (amount ``C`` and length ``L`` along the line of action; a zero length means no relief);
    `shape`: ``"linear"`` or ``"parabolic"``.
    """

    tip_relief_m: float = 0.0
    tip_length_m: float = 0.0
    root_relief_m: float = 0.0
    root_length_m: float = 0.0
    shape: str = "linear"

    @staticmethod
    def _ramp(depth, length, shape, xp):
        """``C f(depth/L)`` for ``depth > 0`` else 0 (0 everywhere when ``L = 0``)."""
        if length == 0.0:
            return 0.0 * depth
        u = xp.maximum(depth / length, 0.0)
        return u if shape == "linear" else u * u

    @staticmethod
    def _ramp_slope(depth, length, shape, xp):
        """``d f(depth/L) / d depth``: ``1/L`` (linear) or ``2 u / L`` (parabolic) for ``depth > 0``, else 0."""
        if length == 0.0:
            return 0.0 * depth
        inside = xp.where(depth > 0.0, 1.0, 0.0)
        return inside / length if shape == "linear" else 2.0 * xp.maximum(depth / length, 0.0) / length

    def deviation(self, xi, xi_root: float, xi_tip: float, xp=np):
        """``e(xi)`` [m] of this flank, `xi` its roll distance from its base tangency [m]."""
        xi = xp.asarray(xi)
        tip = self._ramp(xi - (xi_tip - self.tip_length_m), self.tip_length_m, self.shape, xp)
        root = self._ramp((xi_root + self.root_length_m) - xi, self.root_length_m, self.shape, xp)
        return self.tip_relief_m * tip + self.root_relief_m * root

    def slope(self, xi, xi_root: float, xi_tip: float, xp=np):
        """``de/dxi`` [-] of this flank (:meth:`deviation`'s derivative; one-sided: 0 at a relief start)."""
        xi = xp.asarray(xi)
        tip = self._ramp_slope(xi - (xi_tip - self.tip_length_m), self.tip_length_m, self.shape, xp)
        root = self._ramp_slope((xi_root + self.root_length_m) - xi, self.root_length_m, self.shape, xp)
        return self.tip_relief_m * tip - self.root_relief_m * root


@dataclass(frozen=True)
class ProfileModification:
    """Relief of both flanks; ``e = e_p(xi_p) + e_g(xi_g)`` (module docstring).

    **Arguments:** `pinion`, `gear`: :class:`FlankRelief` (default: none).
    """

    pinion: FlankRelief = FlankRelief()
    gear: FlankRelief = FlankRelief()

    def deviation(self, pair: GearPair, xi_p, xp=np):
        """Composite ``e_j`` [m] of pairs at `xi_p` (from ``T_1``) on `pair`."""
        xi_p = xp.asarray(xi_p)
        length = pair.line_of_action_m
        e_p = self.pinion.deviation(xi_p, pair.contact_start_m, pair.contact_end_m, xp)
        e_g = self.gear.deviation(length - xi_p, length - pair.contact_end_m, length - pair.contact_start_m, xp)
        return e_p + e_g

    def slope(self, pair: GearPair, xi_p, xp=np):
        """``de_j/dxi_p = e_p'(xi_p) - e_g'(L - xi_p)`` [-]: the composite deviation's rate along the
        line of action (a pair's ``de_j/dt`` is this times ``R_bp Omega_p``)."""
        xi_p = xp.asarray(xi_p)
        length = pair.line_of_action_m
        s_p = self.pinion.slope(xi_p, pair.contact_start_m, pair.contact_end_m, xp)
        s_g = self.gear.slope(length - xi_p, length - pair.contact_end_m, length - pair.contact_start_m, xp)
        return s_p - s_g

    def starts(self, pair: GearPair) -> tuple[float, ...]:
        """Positions [m] from ``T_1`` where a relief of non-zero amount begins (where ``e`` has a
        kink and ``de/dt`` jumps): pinion tip ``x_E - L``, pinion root ``x_A + L``, gear tip
        ``x_A + L``, gear root ``x_E - L`` (arithmetic on `pair`'s numbers: they may be traced)."""
        xa, xe = pair.contact_start_m, pair.contact_end_m
        ends = ((self.pinion.tip_relief_m, xe - self.pinion.tip_length_m),
                (self.pinion.root_relief_m, xa + self.pinion.root_length_m),
                (self.gear.tip_relief_m, xa + self.gear.tip_length_m),
                (self.gear.root_relief_m, xe - self.gear.root_length_m))
        return tuple(x for amount, x in ends if amount > 0.0)

    @property
    def is_zero(self) -> bool:
        """No relief on either flank (every amount zero)."""
        return all(getattr(flank, name) == 0.0 for flank in (self.pinion, self.gear)
                   for name in ("tip_relief_m", "root_relief_m"))


def _amount(key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise ConfigError(key, value, "a relief amount >= 0 (finite)")
    return float(value)


def _length(key: str, value, path_mm: float) -> float:
    allowed = f"a relief length in [0, {path_mm:.4f}] mm (the path of contact)"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(key, value, allowed)
    if not 0.0 <= value <= path_mm:
        raise ConfigError(key, value, allowed)
    return float(value)


def profile_modification(pair: GearPair, section: str = "profile", **values) -> ProfileModification:
    """Checked :class:`ProfileModification` from engineering units (config keys of [profile]).

    Keys (all optional, default 0 / "linear"): ``pinion_tip_relief_um``,
    ``pinion_tip_relief_length_mm``, ``gear_tip_relief_um``, ``gear_tip_relief_length_mm``,
    ``pinion_root_relief_um``, ``pinion_root_relief_length_mm``, ``gear_root_relief_um``,
    ``gear_root_relief_length_mm``, ``shape``. Amounts must be >= 0, lengths in
    ``[0, x_E - x_A]``, shape one of :data:`SHAPES`; anything else raises
    :class:`~hbgear.errors.ConfigError` naming ``section.key``.
    """
    path_mm = (pair.contact_end_m - pair.contact_start_m) * 1e3
    names = [f"{flank}_{end}_relief{unit}" for flank in ("pinion", "gear") for end in ("tip", "root")
             for unit in ("_um", "_length_mm")]
    unknown = [name for name in values if name not in (*names, "shape")]
    if unknown:
        raise ConfigError(f"{section}.{unknown[0]}", values[unknown[0]],
                          "not a known key; allowed keys: " + ", ".join((*names, "shape")))
    shape = values.get("shape", "linear")
    if shape not in SHAPES:
        raise ConfigError(f"{section}.shape", shape, "one of " + ", ".join(repr(s) for s in SHAPES))

    def flank(name: str) -> FlankRelief:
        parts = {}
        for end in ("tip", "root"):
            amount_key, length_key = f"{name}_{end}_relief_um", f"{name}_{end}_relief_length_mm"
            parts[f"{end}_relief_m"] = _amount(f"{section}.{amount_key}", values.get(amount_key, 0.0)) * 1e-6
            parts[f"{end}_length_m"] = _length(f"{section}.{length_key}", values.get(length_key, 0.0), path_mm) * 1e-3
        return FlankRelief(**parts, shape=shape)

    return ProfileModification(flank("pinion"), flank("gear"))
