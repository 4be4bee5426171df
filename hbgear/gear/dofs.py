r"""Degrees of freedom of the gear pair: rigid or on bearings, with or without shafts (MODEL.md section 10).

**Physical coordinates** ``r`` (SI): the rotations as base-circle arc lengths -- ``a_p = R_bp theta_p``,
``a_g = R_bg theta_g`` and, with :class:`Shafts`, the drive inertia ``a_d = R_bp theta_d`` and the load
inertia ``a_l = R_bg theta_l`` -- and, with :class:`Bearings`, the centre translations ``y_p, x_p,
y_g, x_g`` along (``y``, the pinion's ``+y`` closing the mesh) and across (``x``) the line of action.
Their kinetic energy is ``1/2 r'^T M_r r'`` with the diagonal ``M_r = diag(J_p/R_bp^2, J_g/R_bg^2,
J_d/R_bp^2, J_l/R_bg^2, M_p, M_p, M_g, M_g)`` (the entries present).

**Generalised coordinates** ``q`` with ``r = P q + r_s`` (``P`` constant, :meth:`DofLayout.projection`):

- ``q[0] = delta = a_p - a_g + y_p - y_g``, the dynamic transmission error;
- ``q[1] = u``: the output body's displacement (``a_l`` with shafts, else ``a_g``) about its static
  value (boundaries ``"spring"`` / ``"reaction"``; the ``"torques"`` boundary eliminates it, below);
- the translations ``y_p, x_p, y_g, x_g`` about their static deflections ``-N/k_py, 0, +N/k_gy, 0``;
- the shaft twists ``t_d = a_d - a_p - t_d,s``, ``t_l = a_g - a_l - t_l,s`` about the static twists
  ``t_d,s = t_l,s = N / k`` (``k`` the shaft's stiffness at the base radius, ``k_t / R^2``).

So ``a_out = u + u_s``, ``a_g = a_out + t_l``, ``a_p = delta + a_g - y_p + y_g``, ``a_d = a_p + t_d``:
every element sees its own physical quantity, ``M = P^T M_r P`` and ``Q = P^T Q_r`` (virtual work).
The mesh acts on ``delta``, a shaft on its twist, a bearing on its translation, the soft output
spring on ``u`` -- each a coordinate of its own -- and the friction torques and forces and the
applied torques on the physical coordinates through ``P``. The static offsets ``r_s`` keep
``delta``, the twists and the translations free of static load, as the soft spring's wind-up does
for ``u``.

**The "torques" boundary** has no force on the free rigid rotation (every arc moving together,
the direction ``P_u`` of ``u``), and its forces do not depend on it (LTI, LTV). Eliminating ``u''``
from ``M q'' = Q`` is the Schur complement of ``M_uu``, which is the projection
``P_eff = P_q - P_u G``, ``G = M_uu^{-1} M_uq``: ``M = P_eff^T M_r P_eff``, ``Q = P_eff^T Q_r``
(the coordinates measured in the frame that moves with the rigid rotation's momentum). Rigid
bearings and no shafts give ``m_e delta'' = N - F_mesh + m_e (T_fp/(R_bp m_p) - T_fg/(R_bg m_g))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from jax.tree_util import register_dataclass

__all__ = ["Bearings", "Shafts", "DofLayout", "dof_layout", "TRANSLATIONS", "ROTATIONS"]

#: Centre translations (MODEL.md section 10), in the order of the coordinates.
TRANSLATIONS = ("y_p", "x_p", "y_g", "x_g")
#: Rotations as base-circle arcs: pinion, gear, drive and load inertia.
ROTATIONS = ("a_p", "a_g", "a_d", "a_l")


@register_dataclass
@dataclass(frozen=True)
class Bearings:
    """Centre masses and bearing springs/dampers of pinion and gear (MODEL.md section 10), SI.

    **Arguments:** `mass_pinion_kg`, `mass_gear_kg`: translating masses ``M_p``, ``M_g`` [kg];
    `k_pinion_loa_N_per_m`, `k_pinion_oloa_N_per_m`, `k_gear_loa_N_per_m`, `k_gear_oloa_N_per_m`:
    bearing stiffness along (LOA, ``y``) and across (OLOA, ``x``) the line of action [N/m];
    `damping_ratio`: ``zeta_b``, each direction's damper ``c = 2 zeta_b sqrt(k M)`` [-].
    """

    mass_pinion_kg: float
    mass_gear_kg: float
    k_pinion_loa_N_per_m: float
    k_pinion_oloa_N_per_m: float
    k_gear_loa_N_per_m: float
    k_gear_oloa_N_per_m: float
    damping_ratio: float

    @property
    def masses(self) -> tuple:
        """``(M_p, M_p, M_g, M_g)`` [kg], in the order of :data:`TRANSLATIONS`."""
        return (self.mass_pinion_kg, self.mass_pinion_kg, self.mass_gear_kg, self.mass_gear_kg)

    @property
    def stiffnesses(self) -> tuple:
        """``(k_py, k_px, k_gy, k_gx)`` [N/m]."""
        return (self.k_pinion_loa_N_per_m, self.k_pinion_oloa_N_per_m, self.k_gear_loa_N_per_m,
                self.k_gear_oloa_N_per_m)

    @property
    def dampings(self) -> tuple:
        """``c = 2 zeta_b sqrt(k M)`` per direction [N s/m]."""
        return tuple(2.0 * self.damping_ratio * (k * m) ** 0.5 for k, m in zip(self.stiffnesses, self.masses))


@register_dataclass
@dataclass(frozen=True)
class Shafts:
    """Torsional shafts from a drive inertia to the pinion and from the gear to a load inertia, SI.

    The input torque acts on the drive inertia, the output boundary (torque, soft spring or
    reaction) on the load inertia. **Arguments:** `inertia_drive_kgm2`, `inertia_load_kgm2`
    ``J_d``, ``J_l`` [kg m^2]; `stiffness_drive_Nm_per_rad`, `stiffness_load_Nm_per_rad` ``k_d``,
    ``k_l`` [N m/rad]; `damping_ratio_drive`, `damping_ratio_load`: each shaft's damper
    ``c_t = 2 zeta sqrt(k_t J_1 J_2 / (J_1 + J_2))`` [N m s/rad] (the ratio of the shaft's own
    two-inertia mode).
    """

    inertia_drive_kgm2: float
    inertia_load_kgm2: float
    stiffness_drive_Nm_per_rad: float
    stiffness_load_Nm_per_rad: float
    damping_ratio_drive: float
    damping_ratio_load: float

    def torsional_damping(self, inertia_pinion, inertia_gear) -> tuple:
        """``(c_d, c_l)`` [N m s/rad] of the two shafts given ``J_p``, ``J_g``."""
        out = []
        for zeta, k, j1, j2 in ((self.damping_ratio_drive, self.stiffness_drive_Nm_per_rad, self.inertia_drive_kgm2,
                                 inertia_pinion),
                                (self.damping_ratio_load, self.stiffness_load_Nm_per_rad, self.inertia_load_kgm2,
                                 inertia_gear)):
            out.append(2.0 * zeta * (k * j1 * j2 / (j1 + j2)) ** 0.5)
        return tuple(out)


@dataclass(frozen=True)
class DofLayout:
    """The structure of the coordinates (no data): which exist, and ``P`` of ``r = P q + r_s``.

    **Fields:** `physical`: names of ``r`` (:data:`ROTATIONS` present, then :data:`TRANSLATIONS`
    with bearings); `generalized`: names of ``q`` before elimination (``delta, u, y_p, x_p, y_g,
    x_g, t_d, t_l``, those present); `eliminated`: the name of the coordinate the ``"torques"``
    boundary removes (``"u"``) or ``None``; `matrix`: ``P`` over all of `generalized` (numpy).
    """

    physical: tuple
    generalized: tuple
    eliminated: str | None
    matrix: np.ndarray

    @property
    def coordinates(self) -> tuple:
        """Names of the model's coordinates ``q`` (without the eliminated one)."""
        return tuple(n for n in self.generalized if n != self.eliminated)

    @property
    def ndof(self) -> int:
        return len(self.coordinates)

    def index(self, name: str) -> int:
        """Position of coordinate `name` in ``q``."""
        return self.coordinates.index(name)

    @property
    def output_body(self) -> str:
        """The physical coordinate of the output boundary: ``a_l`` with shafts, else ``a_g``."""
        return "a_l" if "a_l" in self.physical else "a_g"

    @property
    def input_body(self) -> str:
        """The physical coordinate the input torque acts on: ``a_d`` with shafts, else ``a_p``."""
        return "a_d" if "a_d" in self.physical else "a_p"

    @property
    def rotations(self) -> tuple:
        return tuple(n for n in self.physical if n in ROTATIONS)


@lru_cache(maxsize=None)
def dof_layout(boundary: str, bearings: bool, shafts: bool) -> DofLayout:
    """The :class:`DofLayout` of a structure (module docstring): ``P`` from
    ``a_out = u``, ``a_g = a_out + t_l``, ``a_p = delta + a_g - y_p + y_g``, ``a_d = a_p + t_d``."""
    physical = ("a_p", "a_g") + (("a_d", "a_l") if shafts else ()) + (TRANSLATIONS if bearings else ())
    generalized = ("delta", "u") + (TRANSLATIONS if bearings else ()) + (("t_d", "t_l") if shafts else ())
    col = {n: i for i, n in enumerate(generalized)}
    rows = {}

    def unit(name):
        v = np.zeros(len(generalized))
        v[col[name]] = 1.0
        return v

    out = unit("u")
    if shafts:
        rows["a_l"] = out
        rows["a_g"] = out + unit("t_l")
    else:
        rows["a_g"] = out
    rows["a_p"] = unit("delta") + rows["a_g"]
    if bearings:
        rows["a_p"] = rows["a_p"] - unit("y_p") + unit("y_g")
        for name in TRANSLATIONS:
            rows[name] = unit(name)
    if shafts:
        rows["a_d"] = rows["a_p"] + unit("t_d")
    matrix = np.stack([rows[n] for n in physical])
    return DofLayout(physical, generalized, "u" if boundary == "torques" else None, matrix)
