r"""The spur-gear pair with tooth friction as a periodic mechanical system (MODEL.md sections 2-4).

Coordinates (SI):

- boundary ``"torques"``: one coordinate, the dynamic transmission error (DTE) ``delta`` [m];
- boundary ``"spring"`` / ``"reaction"``: ``q = (delta, u)`` with ``u = R_bg (theta_g - theta_g,s)``
  [m] the gear's base-circle displacement about its static wind-up ``theta_g,s`` on the soft
  output spring, so that ``R_bp theta_p = delta + u + u_s``.
- with ``bearings`` (MODEL.md section 10) the centre translations ``(y_p, x_p, y_g, x_g)`` follow,
  with ``shafts`` the twists ``(t_d, t_l)`` of the drive and load shafts; the general layout is
  :class:`DofLayout` (physical coordinates ``r = P q + r_s``, ``M = P^T M_r P``, ``Q = P^T Q_r``),
  of which the two layouts above are the rigid-bearing, shaftless case.

Equations of motion ``M q'' = Q(t, q, q')`` with, for two coordinates (``m_p = J_p/R_bp^2``,
``m_g = J_g/R_bg^2``; the second row is the sum of the pinion and gear equations, so ``M`` is
symmetric)::

    [m_p   m_p      ] [delta'']   [ T_p/R_bp - F_mesh + T_fp/R_bp                                   ]
    [m_p   m_p + m_g] [u''    ] = [ T_p/R_bp + T_fp/R_bp + T_fg/R_bg - T_g/R_bg - k_u (u+u_s) - c_u u' ]

and for ``delta`` alone ``m_e delta'' = N - F_mesh + m_e (T_fp/(R_bp m_p) - T_fg/(R_bg m_g))``,
``N = T_p / R_bp``, ``1/m_e = 1/m_p + 1/m_g``. The mesh force comes from the model's ``mesh``
(:mod:`hbgear.gear.mesh`): the paper's ``F_mesh = k(t) g(delta - eps) + c(t) (delta' - eps')``, or
per-pair contact ``F_mesh = sum_j F_j`` (MODEL.md section 9); the friction torques are
``T_fp = -sum_j mu_j N_j xi_p,j``, ``T_fg = +sum_j mu_j N_j xi_g,j`` (MODEL.md section 3).

The generalised force is split into a part that is affine in ``(q, q')`` with periodic
coefficients (``part="linear"``; harmonic balance turns it into exact convolution matrices) and
the rest (``part="nonlinear"``; harmonic balance evaluates it by alternating frequency-time).
Which terms are linear depends on the coupling (LTI / LTV / NLTV), the formulation (A / B) and
backlash. All functions take the mesh phase ``s`` in [0, 1) and an array module ``xp``
(``numpy`` or ``jax.numpy``): the time integrator and the harmonic balance evaluate the same
equations.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import jax
import numpy as np
from jax.tree_util import register_dataclass

from .dofs import Bearings, Shafts, dof_layout
from .friction import FrictionLaw
from .mesh import PAIR_SLOTS, PairContact, RectangularMesh

jax.config.update("jax_enable_x64", True)  # hbgear computes in float64 (see hbgear.engine)

__all__ = ["GearPairModel", "PAIR_SLOTS"]

COUPLINGS = ("LTI", "LTV", "NLTV")
FORMULATIONS = ("A", "B")
BOUNDARIES = ("torques", "spring", "reaction")
LTI_FRICTION = ("excitation", "damping", "both")


@register_dataclass
@dataclass(frozen=True)
class GearPairModel:
    """All parameters of the gear pair in SI units, as a JAX pytree.

    Float fields are pytree data (they may be traced: continuation in torque, damping, ...);
    the string fields choose the structure of the equations and are static.

    **Arguments:**

    - `teeth_pinion`, `teeth_gear`: ``Z_p``, ``Z_g`` [-].
    - `base_radius_pinion_m`, `base_radius_gear_m`: ``R_bp``, ``R_bg`` [m].
    - `contact_start_m`: ``x_A`` [m]; `base_pitch_m`: ``p_b`` [m];
      `line_of_action_m`: ``L`` [m]; `contact_ratio`: ``Gamma`` [-].
    - `inertia_pinion_kgm2`, `inertia_gear_kgm2`: ``J_p``, ``J_g`` [kg m^2].
    - `k_max_N_per_m`, `k_min_N_per_m`: mesh stiffness in double / single contact [N/m] (the
      rectangular mesh's; with per-pair contact only for information: the extremes of ``k(s)``).
    - `damping_ratio`: mesh damping ratio ``zeta`` [-], ``c = 2 zeta sqrt(k_mean m_e)``.
    - `backlash_m`: total backlash ``2b`` [m] (used when `contact` is ``"backlash"``).
    - `ste_amplitude_m`, `ste_phase_rad`: unloaded static transmission error per mesh order.
    - `torque_pinion_Nm`: input torque ``T_p`` [N m].
    - `friction`: a :class:`~hbgear.gear.friction.FrictionLaw`.
    - `face_width_m`: face width [m] (load per unit width for load-dependent laws).
    - `spring_stiffness_ratio`: ``k_mean R_bg^2 / k_b`` [-]; `spring_damping_ratio`: damping
      ratio of the soft output mode [-].
    - `bearings`: ``None`` (rigid bearings) or :class:`~hbgear.gear.dofs.Bearings` (centre
      translations, MODEL.md section 10); `shafts`: ``None`` or :class:`~hbgear.gear.dofs.Shafts`
      (drive and load inertias on torsional shafts). Coordinates: :mod:`hbgear.gear.dofs`.
    - `coupling`: ``"LTI" | "LTV" | "NLTV"``; `formulation`: ``"A" | "B"``;
      `boundary`: ``"torques" | "spring" | "reaction"``;
      `damping_model`: ``"constant" | "proportional"`` (``c(t) = c k(t)/k_mean``);
      `contact`: ``"linear"`` (teeth never separate) or ``"backlash"``;
      `normal_loads`: ``"compressive"`` (MODEL.md section 11, :meth:`friction_loads`) or
      ``"signed"`` (``sigma_j N`` / ``sigma_j F_mesh`` whatever the contact: not a physical model,
      the linearisation along solutions with drive-flank contact and ``F_mesh > 0``; see
      :func:`hbgear.gear.system.linear_equivalent`);
      `lti_friction` (LTI only): the friction as the Fourier excitation of the nominal friction
      torques (``"excitation"``, Eq. 10), as the energy-equivalent viscous damper at the mesh
      (``"damping"``, :meth:`lti_friction_damping_Ns_per_m`) or both (``"both"``).
    - `mesh`: the tooth mesh (:mod:`hbgear.gear.mesh`): :class:`~hbgear.gear.mesh.RectangularMesh`
      (default, the paper's) or :class:`~hbgear.gear.mesh.PairContactMesh` (per-pair contact, which
      damps each pair in proportion to its stiffness: `damping_model` must be ``"proportional"``).
    """

    teeth_pinion: float
    teeth_gear: float
    base_radius_pinion_m: float
    base_radius_gear_m: float
    contact_start_m: float
    base_pitch_m: float
    line_of_action_m: float
    contact_ratio: float
    inertia_pinion_kgm2: float
    inertia_gear_kgm2: float
    k_max_N_per_m: float
    k_min_N_per_m: float
    damping_ratio: float
    backlash_m: float
    ste_amplitude_m: Any
    ste_phase_rad: Any
    torque_pinion_Nm: float
    friction: FrictionLaw
    face_width_m: float
    spring_stiffness_ratio: float
    spring_damping_ratio: float
    bearings: Bearings | None = None
    shafts: Shafts | None = None
    coupling: str = field(default="LTV", metadata=dict(static=True))
    formulation: str = field(default="A", metadata=dict(static=True))
    boundary: str = field(default="spring", metadata=dict(static=True))
    damping_model: str = field(default="constant", metadata=dict(static=True))
    contact: str = field(default="linear", metadata=dict(static=True))
    normal_loads: str = field(default="compressive", metadata=dict(static=True))
    mesh: Any = RectangularMesh()
    lti_friction: str = field(default="excitation", metadata=dict(static=True))

    def __post_init__(self):
        # pytree unflattening may pass placeholders; only check real strings
        for name, allowed in (
            ("coupling", COUPLINGS),
            ("formulation", FORMULATIONS),
            ("boundary", BOUNDARIES),
            ("damping_model", ("constant", "proportional")),
            ("contact", ("linear", "backlash")),
            ("normal_loads", ("compressive", "signed")),
            ("lti_friction", LTI_FRICTION),
        ):
            value = getattr(self, name)
            if isinstance(value, str) and value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        # LTI is linear with quasi-static friction loads (MODEL.md section 3)
        if isinstance(self.coupling, str) and self.coupling == "LTI":
            if isinstance(self.formulation, str) and self.formulation == "B":
                raise ValueError("formulation 'B' (dynamic normal loads) needs coupling 'LTV' or 'NLTV', not 'LTI'")
            if isinstance(self.contact, str) and self.contact == "backlash":
                raise ValueError("contact 'backlash' needs coupling 'LTV' or 'NLTV', not 'LTI' (LTI is linear)")
        elif isinstance(self.coupling, str) and isinstance(self.lti_friction, str) and self.lti_friction != "excitation":
            raise ValueError(f"lti_friction {self.lti_friction!r} needs coupling 'LTI', not {self.coupling!r}")
        if getattr(self.mesh, "per_pair", False) is True and self.damping_model == "constant":
            raise ValueError("per-pair contact damps each pair as c k_j/k_mean (MODEL.md section 9): "
                             "damping_model must be 'proportional'")

    def replace(self, **changes) -> GearPairModel:
        return replace(self, **changes)

    # -- derived constants -------------------------------------------------------------------
    @property
    def layout(self):
        """The :class:`~hbgear.gear.dofs.DofLayout` of this structure (boundary, bearings, shafts)."""
        return dof_layout(self.boundary, self.bearings is not None, self.shafts is not None)

    @property
    def ndof(self) -> int:
        return self.layout.ndof

    @property
    def k_mean_N_per_m(self):
        """Mean mesh stiffness [N/m]: ``k_max (Gamma - 1) + k_min (2 - Gamma)`` (rectangular), the
        mesh-period mean of ``sum_j k_pair(xi_j)`` (per-pair contact)."""
        return self.mesh.k_mean(self)

    @property
    def mass_pinion_kg(self):
        """``m_p = J_p / R_bp^2`` [kg]."""
        return self.inertia_pinion_kgm2 / self.base_radius_pinion_m**2

    @property
    def mass_gear_kg(self):
        """``m_g = J_g / R_bg^2`` [kg]."""
        return self.inertia_gear_kgm2 / self.base_radius_gear_m**2

    @property
    def mass_equivalent_kg(self):
        """``m_e = 1 / (1/m_p + 1/m_g)`` [kg]."""
        return 1.0 / (1.0 / self.mass_pinion_kg + 1.0 / self.mass_gear_kg)

    @property
    def mesh_damping_Ns_per_m(self):
        """``c = 2 zeta sqrt(k_mean m_e)`` [N s/m]."""
        return 2.0 * self.damping_ratio * (self.k_mean_N_per_m * self.mass_equivalent_kg) ** 0.5

    @property
    def normal_load_N(self):
        """Quasi-static total normal load ``N = T_p / R_bp`` [N]."""
        return self.torque_pinion_Nm / self.base_radius_pinion_m

    @property
    def torque_gear_Nm(self):
        """Applied output torque ``T_g`` [N m]: balances ``T_p`` for ``"torques"``, else 0."""
        if self.boundary == "torques":
            return self.torque_pinion_Nm * self.base_radius_gear_m / self.base_radius_pinion_m
        return 0.0 * self.torque_pinion_Nm

    @property
    def spring_stiffness_N_per_m(self):
        """Soft output spring in ``u`` coordinates, ``k_u = k_b / R_bg^2 = k_mean / ratio`` [N/m]."""
        if self.boundary != "spring":
            return 0.0 * self.k_max_N_per_m
        return self.k_mean_N_per_m / self.spring_stiffness_ratio

    @property
    def spring_damping_Ns_per_m(self):
        """``c_u = 2 zeta_b sqrt(k_u M_uu)`` [N s/m] (``M_uu`` = :attr:`rigid_mass_kg`, ``m_p + m_g``
        without shafts), the soft mode's own damping."""
        mass = self.rigid_mass_kg
        return 2.0 * self.spring_damping_ratio * (self.spring_stiffness_N_per_m * mass) ** 0.5

    @property
    def spring_torsional_stiffness_Nm_per_rad(self):
        """``k_b = k_mean R_bg^2 / ratio`` [N m/rad]."""
        return self.spring_stiffness_N_per_m * self.base_radius_gear_m**2

    @property
    def rigid_mass_kg(self):
        """Mass of the free rigid rotation, every arc moving together [kg]: ``m_p + m_g`` (+ the drive
        and load inertias ``J_d/R_bp^2 + J_l/R_bg^2`` with shafts), ``M_uu`` of the ``u`` coordinate."""
        masses = self.physical_masses()
        total = masses["a_p"] + masses["a_g"]
        if self.shafts is not None:
            total = total + masses["a_d"] + masses["a_l"]
        return total

    def physical_masses(self) -> dict:
        """The diagonal ``M_r`` [kg] by physical coordinate (:mod:`hbgear.gear.dofs`)."""
        masses = {"a_p": self.mass_pinion_kg, "a_g": self.mass_gear_kg}
        if self.shafts is not None:
            masses["a_d"] = self.shafts.inertia_drive_kgm2 / self.base_radius_pinion_m**2
            masses["a_l"] = self.shafts.inertia_load_kgm2 / self.base_radius_gear_m**2
        if self.bearings is not None:
            masses.update(zip(("y_p", "x_p", "y_g", "x_g"), self.bearings.masses))
        return masses

    def projection(self) -> dict:
        """``P`` of ``r = P q + r_s`` by physical coordinate: a list over ``q`` of Python floats (the
        structure) or, for the ``"torques"`` boundary, the Schur projection ``P_q - P_u G`` whose
        rotation entries depend on the masses (:mod:`hbgear.gear.dofs`)."""
        lay = self.layout
        keep = [lay.generalized.index(n) for n in lay.coordinates]
        rows = {name: [float(lay.matrix[i, j]) for j in keep] for i, name in enumerate(lay.physical)}
        if lay.eliminated is None:
            return rows
        e = lay.generalized.index(lay.eliminated)
        masses = self.physical_masses()
        moving = [(name, i) for i, name in enumerate(lay.physical) if lay.matrix[i, e] != 0.0]
        total = self.rigid_mass_kg
        for jj, j in enumerate(keep):
            terms = [masses[name] * lay.matrix[i, j] for name, i in moving if lay.matrix[i, j] != 0.0]
            if not terms:
                continue
            share = sum(terms[1:], terms[0]) / total  # G_j = M_uj / M_uu
            for name, i in moving:
                rows[name][jj] = rows[name][jj] - share * lay.matrix[i, e]
        return rows

    def mass_matrix(self, xp=np):
        """``M = P^T M_r P`` [kg], shape ``(ndof, ndof)``."""
        masses, rows, n = self.physical_masses(), self.projection(), self.ndof
        matrix = [[0.0] * n for _ in range(n)]
        for name, row in rows.items():
            for j in range(n):
                for k in range(n):
                    term = _scaled(masses[name], row[j])
                    term = None if term is None else _scaled(term, row[k])
                    if term is not None:
                        matrix[j][k] = term if _is_zero(matrix[j][k]) else matrix[j][k] + term
        return xp.asarray(matrix)

    def speeds(self, omega_pinion):
        """``(Omega_p, Omega_g, w_m)`` [rad/s] from the pinion speed."""
        return omega_pinion, omega_pinion * self.teeth_pinion / self.teeth_gear, omega_pinion * self.teeth_pinion

    # -- mesh-phase functions ------------------------------------------------------------------
    def pair_positions(self, s, xp=np):
        """Contact positions and shares of the pair slots at mesh phase ``s``.

        Returns ``(xi_p, xi_g, in_contact, sigma)``, each of shape ``(PAIR_SLOTS,) + s.shape``:
        ``xi_p,k = x_A + p_b (s + k)`` [m], ``xi_g,k = L - xi_p,k``, contact while
        ``s + k < Gamma``, equal load shares ``sigma_k`` among the pairs in contact (Eq. 13).
        """
        s = xp.asarray(s)
        slots = xp.reshape(xp.arange(PAIR_SLOTS, dtype=s.dtype), (PAIR_SLOTS,) + (1,) * s.ndim)
        age = s[None] + slots
        xi_p = self.contact_start_m + self.base_pitch_m * age
        xi_g = self.line_of_action_m - xi_p
        in_contact = xp.where(age < self.contact_ratio, 1.0, 0.0)
        sigma = in_contact / xp.sum(in_contact, axis=0)[None]
        return xi_p, xi_g, in_contact, sigma

    def mesh_stiffness(self, s, xp=np):
        """``k(s)`` [N/m]: the rectangular pulse (Eq. 14), or ``sum_j k_pair(xi_j)`` over the path."""
        return self.mesh.stiffness(self, s, xp)

    def mesh_damping(self, s, xp=np):
        """``c(s)`` [N s/m]: constant, or proportional to ``k(s)``."""
        return self.mesh.damping(self, s, xp)

    def static_transmission_error(self, s, omega_mesh, xp=np):
        """Unloaded STE ``eps = sum_n A_n cos(2 pi n s + phi_n)`` [m] and ``eps'`` [m/s]."""
        amp = xp.asarray(self.ste_amplitude_m)
        if amp.shape[0] == 0:
            zero = 0.0 * s
            return zero, zero
        order = xp.arange(1, amp.shape[0] + 1)
        phase = 2 * np.pi * order[:, None] * xp.ravel(s)[None] + xp.asarray(self.ste_phase_rad)[:, None]
        eps = xp.reshape(xp.sum(amp[:, None] * xp.cos(phase), axis=0), xp.shape(s))
        # omega_mesh may carry a batch axis that s does not (read-outs of many points)
        deps = -omega_mesh * xp.reshape(xp.sum((amp * order)[:, None] * xp.sin(phase), axis=0), xp.shape(s))
        return eps, deps

    def loaded_static_transmission_error(self, s, omega_mesh, xp=np):
        """Loaded STE fluctuation ``eps + D(s) - <D>`` [m] (LTI excitation, Eq. 10), ``D`` the
        static deflection of the mesh (``N/k(s)`` for the rectangular one)."""
        eps, _ = self.static_transmission_error(s, omega_mesh, xp)
        return eps + self.normal_load_N * self.mesh.compliance_fluctuation(self, s, xp)

    def static_dte(self, s, omega_pinion, xp=np):
        """The loaded static TE ``delta_s = eps + D(s)`` [m] (plus half the backlash: the drive flank
        carries the load) at phases `s`; ``D = N/k(s)`` (rectangular) or the per-pair static contact."""
        eps, _ = self.static_transmission_error(s, self.speeds(omega_pinion)[2], xp)
        delta = eps + self.mesh.static_deflection(self, s, xp)
        if self.contact == "backlash":
            delta = delta + 0.5 * self.backlash_m
        return delta

    # -- velocities, forces ---------------------------------------------------------------------
    def angular_velocities(self, qd, omega_pinion, nominal: bool):
        """Total speeds ``(Omega_p + theta_p', Omega_g + theta_g')`` [rad/s].

        ``theta_p' = a_p'/R_bp``, ``theta_g' = a_g'/R_bg`` (two coordinates: ``a_p' = delta' + u'``,
        ``a_g' = u'``); nominal speeds when `nominal` (LTI, LTV) or when the free rotation is
        eliminated (``"torques"``: only the vibration relative to it is known).
        """
        return self._speeds_of(("a_p", "a_g"), qd, omega_pinion, nominal)

    def body_speeds(self, qd, omega_pinion):
        """Total speeds [rad/s] of the bodies the input torque and the output boundary act on (the
        drive and load inertias with shafts, else pinion and gear), as :meth:`angular_velocities`."""
        lay = self.layout
        return self._speeds_of((lay.input_body, lay.output_body), qd, omega_pinion, False)

    def _speeds_of(self, bodies, qd, omega_pinion, nominal):
        wp, wg, _ = self.speeds(omega_pinion)
        if nominal or self.layout.eliminated is not None:
            return wp + 0.0 * qd[0], wg + 0.0 * qd[0]
        rows = self.projection()
        return (wp + _combine(rows[bodies[0]], qd) / self.base_radius_pinion_m,
                wg + _combine(rows[bodies[1]], qd) / self.base_radius_gear_m)

    def centre_sliding_velocity(self, qd):
        """``x_p' - x_g'`` [m/s], what the centres add to the sliding velocity (MODEL.md section 10),
        or ``None`` with rigid bearings."""
        if self.bearings is None:
            return None
        lay = self.layout
        return qd[lay.index("x_p")] - qd[lay.index("x_g")]

    def mesh_force(self, s, q, qd, omega_pinion, xp=np):
        """``F_mesh`` [N] of the mesh at ``x = delta - eps``, ``x' = delta' - eps'`` (rectangular:
        ``k g(x) + c x'``; LTI: ``k_mean``, loaded STE)."""
        _, _, wm = self.speeds(omega_pinion)
        if self.coupling == "LTI":
            # Eq. 10: k_mean (delta - d_st) + c (delta' - d_st'), d_st the loaded STE fluctuation;
            # here the pointwise part c eps' of c d_st'; its impulses at the stiffness jumps are
            # dG/dt of lti_step_forcing (harmonic balance: exact Fourier coefficients of the
            # system's derivative_forcing; time integration: velocity kicks).
            eps, deps = self.static_transmission_error(s, wm, xp)
            dst = self.loaded_static_transmission_error(s, wm, xp)
            return self.k_mean_N_per_m * (q[0] - dst) + self.mesh_damping_Ns_per_m * (qd[0] - deps)
        eps, deps = self.static_transmission_error(s, wm, xp)
        return self.mesh.force(self, s, q[0] - eps, qd[0] - deps, wm, xp)

    def pair_contact(self, s, q, qd, omega_pinion, xp=np) -> PairContact:
        """Per-pair contact forces ``F_j`` [N] and flank flags of the mesh
        (:class:`~hbgear.gear.mesh.PairContact`, shapes ``(PAIR_SLOTS,) + s.shape``): ``sigma_j F_mesh``
        and the dead zone's flanks (rectangular), or each pair's own contact (per-pair)."""
        _, _, wm = self.speeds(omega_pinion)
        eps, deps = self.static_transmission_error(s, wm, xp)
        return self.mesh.pairs(self, s, q[0] - eps, qd[0] - deps, wm, xp)

    def contact_events(self, s, q, omega_pinion, xp=np):
        """Functions of ``x = delta - eps`` whose zeros are where the contact gate of the friction
        loads (and, per pair, of the pair dampers) jumps, shape ``(E,) + q[0].shape``, else ``None``.

        Rectangular with backlash, friction and ``normal_loads = "compressive"``: ``(x - b, x + b)``
        -- formulation A's load ``sigma_j N`` switches on and off at ``x = b``; formulation B's
        ``sigma_j max(+-F_mesh, 0)`` jumps where a flank closes with ``F_mesh = c x' != 0``. Per-pair
        contact that may open: every pair's flanks (:meth:`~hbgear.gear.mesh.PairContactMesh.contact_events`),
        where its damper force jumps, whatever the friction.
        """
        per_pair = getattr(self.mesh, "per_pair", False)
        if not per_pair and (self.normal_loads != "compressive" or self.friction.name == "none"):
            return None
        _, _, wm = self.speeds(omega_pinion)
        eps, _ = self.static_transmission_error(s, wm, xp)
        return self.mesh.contact_events(self, s, q[0] - eps, xp)

    def friction_loads(self, s, q, qd, omega_pinion, quasi_static, xp=np):
        """Normal loads ``N_j >= 0`` of the pairs [N] and their part in the linear split.

        `quasi_static`: the quasi-static pair loads ``N_j,s`` of the mesh (``sigma_j N``; per-pair
        contact: the static contact's loads). MODEL.md section 11 (``normal_loads = "compressive"``),
        with ``F_j`` and the flanks of :meth:`pair_contact`: LTI ``N_j,s``; formulation A ``N_j,s``
        while pair ``j``'s drive flank is in contact, else 0 (always, where the pairs cannot
        separate: no backlash and, per pair, no relief); formulation B where the pairs cannot
        separate ``|F_j|`` (a negative ``F_j`` is carried by the back flank), else ``max(F_j, 0)``
        while the drive flank is in contact, ``max(-F_j, 0)`` while the back flank is, 0 apart.
        ``"signed"``: ``N_j,s`` (A) or ``F_j`` (B) at all times.

        **Returns:** ``(normal, affine)``, shape ``(PAIR_SLOTS,) + ...``: ``affine`` is the part of
        the loads that :meth:`generalized_force` puts in the linear part -- ``N_j,s`` (LTI, A),
        ``F_j`` (LTV-B with a linear mesh), 0 otherwise (NLTV; B where pairs separate) -- so
        ``normal - affine`` vanishes while every drive flank is in contact with ``F_j > 0``.
        """
        if self.formulation == "A":
            normal = quasi_static
            if self.normal_loads == "compressive" and not self.mesh_is_linear:
                normal = quasi_static * self.pair_contact(s, q, qd, omega_pinion, xp).drive
            affine = quasi_static
        else:
            contact = self.pair_contact(s, q, qd, omega_pinion, xp)
            signed = contact.force
            if self.normal_loads == "signed":
                normal = signed
            elif self.mesh_is_linear:
                normal = xp.abs(signed)
            else:
                normal = contact.drive * xp.maximum(signed, 0.0) + contact.back * xp.maximum(-signed, 0.0)
            affine = signed if self.mesh_is_linear else 0.0 * signed
        if self.coupling == "NLTV":
            affine = 0.0 * affine
        return normal, affine

    def _pair_friction(self, s, q, qd, omega_pinion, xp=np):
        """:meth:`pair_friction` and the affine part of the loads (:meth:`friction_loads`)."""
        xi_p, xi_g, in_path, _ = self.pair_positions(s, xp)
        sigma, quasi_static = self.mesh.static_loads(self, s, xp)
        nonlinear = self.coupling == "NLTV"
        wp_tot, wg_tot = self.angular_velocities(qd, omega_pinion, nominal=not nonlinear)
        vs = xi_p * wp_tot[None] - xi_g * wg_tot[None]
        centres = self.centre_sliding_velocity(qd) if nonlinear else None
        if centres is not None:
            vs = vs + centres[None]
        vr = xi_p * wp_tot[None] + xi_g * wg_tot[None]
        normal, affine = self.friction_loads(s, q, qd, omega_pinion, quasi_static, xp)
        law_load = normal if nonlinear else quasi_static
        mu = self.friction.mu(vs, vr, law_load / self.face_width_m, xp)
        pairs = {
            "xi_p": xi_p,
            "xi_g": xi_g,
            "in_path": in_path,
            "sigma": sigma,
            "vs": vs,
            "vr": vr,
            "mu": mu,
            "normal": normal,
            "friction": mu * normal,
        }
        return pairs, affine

    def pair_friction(self, s, q, qd, omega_pinion, xp=np):
        """Per-pair sliding velocity, friction coefficient and normal load.

        Returns a dict of arrays of shape ``(PAIR_SLOTS,) + s.shape``: ``xi_p``, ``xi_g`` [m],
        ``in_path`` (1.0 on the path of contact), ``sigma`` (the quasi-static load shares: equal for
        the rectangular mesh, ``N_j,s / N`` emerging from the per-pair static contact), ``vs``,
        ``vr`` [m/s], ``mu`` [-], ``normal`` [N] and ``friction`` =
        ``mu N_j`` [N]. ``mu`` uses the nominal kinematics and the quasi-static load for LTI and
        LTV, the instantaneous kinematics and the load ``N_j`` for NLTV; the normal loads
        ``N_j >= 0`` are those of :meth:`friction_loads` (MODEL.md section 11). Back-flank contact
        keeps the drive flank's positions, arms and sliding velocities (mirror geometry at the
        same phase), so the friction power ``-sum mu_j N_j V_s,j`` stays <= 0.
        """
        return self._pair_friction(s, q, qd, omega_pinion, xp)[0]

    def friction_torques(self, s, q, qd, omega_pinion, xp=np, part="all"):
        """``(T_fp, T_fg)`` [N m]: ``-sum mu_j N_j xi_p,j`` and ``+sum mu_j N_j xi_g,j``.

        `part`: ``"all"``; ``"linear"`` (the loads' affine part of :meth:`friction_loads`) or
        ``"nonlinear"`` (the rest), the split of :meth:`generalized_force`. LTI with
        ``lti_friction`` ``"damping"`` / ``"both"``: the viscous damper ``c_f delta'`` at the mesh
        (its torques ``-R_bp c_f delta'``, ``+R_bg c_f delta'``) replaces / joins the excitation.
        """
        return self.friction_actions(s, q, qd, omega_pinion, xp, part)[:2]

    def friction_actions(self, s, q, qd, omega_pinion, xp=np, part="all"):
        """``(T_fp, T_fg, F_fp, F_fg)``: the friction torques [N m] of :meth:`friction_torques` and
        the OLOA forces on the centres [N], ``F_fp = -sum mu_j N_j``, ``F_fg = +sum mu_j N_j``
        (MODEL.md section 10: ``T_fp = sum_j xi_p,j F_fp,j``); `part` as there."""
        pf, affine = self._pair_friction(s, q, qd, omega_pinion, xp)
        if part == "all":
            friction = pf["friction"]
        else:
            friction = pf["mu"] * (affine if part == "linear" else pf["normal"] - affine)
        total = xp.sum(friction, axis=0)
        t_fp, t_fg = -xp.sum(friction * pf["xi_p"], axis=0), xp.sum(friction * pf["xi_g"], axis=0)
        if self.coupling != "LTI" or self.lti_friction == "excitation":
            return t_fp, t_fg, -total, total
        if self.lti_friction == "damping":  # the damper replaces the friction, its OLOA forces too
            t_fp, t_fg, total = 0.0 * t_fp, 0.0 * t_fg, 0.0 * total
        # the equivalent damper acts at the mesh, along the line of action: torques only
        damper = self.lti_friction_damping_Ns_per_m(omega_pinion, xp) * qd[0]
        return t_fp - self.base_radius_pinion_m * damper, t_fg + self.base_radius_gear_m * damper, -total, total

    def lti_friction_damping_Ns_per_m(self, omega_pinion, xp=np):
        r"""Energy-equivalent viscous damping of the friction loss, ``c_f`` [N s/m] (LTI).

        ``c_f = <sum_j |mu_j| sigma_j N |V_s,j|> / <sum_j sigma_j V_s,j^2>``: the mean friction loss
        of the nominal kinematics with quasi-static loads (paper p. 386, "for one meshing cycle, the
        energy loss is int sum mu_i N_i xi_i d theta_i") over the mean square of the nominal sliding
        velocities, the reference velocity; a damper ``c_f v`` sliding at those velocities
        dissipates that loss (equal energy per cycle, the classical equivalent viscous damping).
        It acts at the mesh on ``delta'``. Means over the mesh period by the quadrature between the
        breakpoints (exact for the Coulomb law's pieces). Zero unless LTI with damping.
        """
        if self.coupling != "LTI" or self.lti_friction == "excitation":
            return 0.0 * omega_pinion
        from ..engine.quadrature import mesh_period_rule

        s, w = mesh_period_rule(self.breakpoint_candidates(xp), 4, xp)
        xi_p, xi_g, _, sigma = self.pair_positions(s, xp)
        wp, wg, _ = self.speeds(omega_pinion)
        vs, vr = xi_p * wp - xi_g * wg, xi_p * wp + xi_g * wg
        mu = self.friction.mu(vs, vr, sigma * self.normal_load_N / self.face_width_m, xp)
        loss = xp.sum(w * xp.sum(xp.abs(mu) * sigma * self.normal_load_N * xp.abs(vs), axis=0))
        return loss / xp.sum(w * xp.sum(sigma * vs * vs, axis=0))

    # -- the split into linear-periodic and nonlinear parts -------------------------------------
    @property
    def mesh_is_linear(self) -> bool:
        """The mesh force is affine in the state: LTI (``k_mean``), or a mesh whose pairs cannot
        separate (no backlash; per pair also no relief, :meth:`~hbgear.gear.mesh.PairContactMesh.is_linear`)."""
        return self.coupling == "LTI" or self.mesh.is_linear(self)

    @property
    def pairs_may_open(self) -> bool:
        """Per-pair contact (MODEL.md section 9) whose pairs can lose contact (relief or backlash):
        its contact events need more located zeros and its formulation A a corner where a loss is born."""
        return bool(getattr(self.mesh, "per_pair", False)) and not self.mesh_is_linear

    @property
    def friction_has_linear_part(self) -> bool:
        """Friction loads with a nonzero affine part (:meth:`friction_loads`): LTI, LTV-A, LTV-B
        without backlash."""
        return self.coupling != "NLTV" and (self.formulation == "A" or self.mesh_is_linear)

    @property
    def friction_is_linear(self) -> bool:
        """Friction is affine in the state (no nonlinear part): LTI; LTV formulation A without
        backlash; with ``normal_loads = "signed"`` also LTV-A with backlash and LTV-B without."""
        if self.coupling == "NLTV":
            return False
        if self.coupling == "LTI" or self.normal_loads == "signed":
            return self.formulation == "A" or self.mesh_is_linear
        return self.formulation == "A" and self.mesh_is_linear

    @property
    def is_linear(self) -> bool:
        return self.mesh_is_linear and self.friction_is_linear

    def generalized_force(self, s, q, qd, omega_pinion, part: str = "all", u_static=0.0, reaction=0.0, xp=np):
        """``Q(s, q, q')``, shape ``(ndof,) + s.shape`` [N].

        **Arguments:**

        - `s`: mesh phase in [0, 1); `q`, `qd`: coordinates [m] and velocities [m/s], shape
          ``(ndof,) + s.shape``; `omega_pinion`: ``Omega_p`` [rad/s].
        - `part`: ``"linear"`` (terms affine in ``q, q'``), ``"nonlinear"`` or ``"all"``; the
          friction splits by its loads (:meth:`friction_loads`: the affine part is linear).
        - `u_static`: the static wind-up ``u_s`` [m] (``"spring"``; see :meth:`static_windup`).
        - `reaction`: output force ``T_g / R_bg`` [N] (``"reaction"``: an unknown of the solver).
        """
        take_mesh = part == "all" or (part == "linear") == self.mesh_is_linear
        take_friction = part == "all" or (self.friction_has_linear_part if part == "linear" else not self.friction_is_linear)
        take_constant = part in ("all", "linear")
        lay, rows = self.layout, self.projection()
        rbp, rbg = self.base_radius_pinion_m, self.base_radius_gear_m
        out = [None] * lay.ndof  # Q, row by row; elements add in a fixed order (mesh, friction, torques, ...)
        if take_mesh:  # the mesh acts on delta = q[0]: virtual work -F_mesh d delta
            out[0] = -self.mesh_force(s, q, qd, omega_pinion, xp)
        if take_friction:
            t_fp, t_fg, f_fp, f_fg = self.friction_actions(s, q, qd, omega_pinion, xp, part)
            actions = {"a_p": t_fp / rbp, "a_g": t_fg / rbg}
            if self.bearings is not None:
                actions |= {"x_p": f_fp, "x_g": f_fg}
            _apply(out, rows, actions)
        if take_constant:
            _apply(out, rows, {lay.input_body: self.torque_pinion_Nm / rbp})
            if lay.eliminated is not None:  # the output torque through the Schur projection ("torques")
                _apply(out, rows, {lay.output_body: -self.torque_gear_Nm / rbg})
            else:  # on u, the output body's own coordinate: the torque, the soft spring
                u = lay.index("u")
                out[u] = _add(out[u], -(self.torque_gear_Nm / rbg + reaction))
                out[u] = _add(out[u], -(self.spring_stiffness_N_per_m * (q[u] + u_static)
                                        + self.spring_damping_Ns_per_m * qd[u]))
            for name, force in self.support_forces(q, qd).items():  # bearings, shafts: own coordinates
                i = lay.index(name)
                out[i] = _add(out[i], -force)
        zero = 0.0 * s
        return xp.stack([zero if row is None else row + zero for row in out])

    def support_forces(self, q, qd) -> dict:
        """Forces of the bearings and shafts on their own coordinates [N] (total, static load
        included): ``k y + c y'`` per translation (``k_py (y_p - N/k_py) = k_py y_p - N``, ``k_gy y_g
        + N``, OLOA without static load) and, per shaft twist, ``(k_t t + c_t t')/R^2 + N``
        (``k_t/R^2`` the shaft's stiffness at the base radius ``R`` of its gear). Empty when rigid."""
        lay, out, n = self.layout, {}, self.normal_load_N
        if self.bearings is not None:
            static = (-n, 0.0, n, 0.0)
            for name, k, c, f in zip(("y_p", "x_p", "y_g", "x_g"), self.bearings.stiffnesses,
                                     self.bearings.dampings, static):
                i = lay.index(name)
                out[name] = k * q[i] + c * qd[i] + f
        if self.shafts is not None:
            sh = self.shafts
            c_d, c_l = sh.torsional_damping(self.inertia_pinion_kgm2, self.inertia_gear_kgm2)
            for name, k, c, radius in (("t_d", sh.stiffness_drive_Nm_per_rad, c_d, self.base_radius_pinion_m),
                                       ("t_l", sh.stiffness_load_Nm_per_rad, c_l, self.base_radius_gear_m)):
                i = lay.index(name)
                out[name] = (k * q[i] + c * qd[i]) / radius**2 + n
        return out

    def bearing_forces(self, q, qd) -> dict:
        """Dynamic bearing forces ``k y + c y'`` [N] (static load included: the mean along the LOA
        is ``-<F_mesh>`` on the pinion, ``+<F_mesh>`` on the gear), keyed ``pinion_loa``,
        ``pinion_oloa``, ``gear_loa``, ``gear_oloa``; empty with rigid bearings."""
        forces = self.support_forces(q, qd)
        names = {"y_p": "pinion_loa", "x_p": "pinion_oloa", "y_g": "gear_loa", "x_g": "gear_oloa"}
        return {label: forces[name] for name, label in names.items() if name in forces}

    def support_losses(self, qd) -> dict:
        """Instantaneous damper powers [W] ``c v^2`` of the bearings (``"bearings"``) and shafts
        (``"shafts"``, ``c_t/R^2 t'^2``), summed over each group; empty when rigid."""
        lay, out = self.layout, {}
        if self.bearings is not None:
            terms = [c * qd[lay.index(name)] ** 2 for name, c in zip(("y_p", "x_p", "y_g", "x_g"),
                                                                    self.bearings.dampings)]
            out["bearings"] = terms[0] + terms[1] + terms[2] + terms[3]
        if self.shafts is not None:
            c_d, c_l = self.shafts.torsional_damping(self.inertia_pinion_kgm2, self.inertia_gear_kgm2)
            out["shafts"] = (c_d / self.base_radius_pinion_m**2 * qd[lay.index("t_d")] ** 2
                             + c_l / self.base_radius_gear_m**2 * qd[lay.index("t_l")] ** 2)
        return out

    def lti_step_forcing(self, s, xp=np):
        """``G(s) = c (D(s) - <D>)`` on the DTE row [N s] for LTI, else ``None`` (``D = N/k(s)``
        rectangular, the static contact's deflection per pair).

        ``-F_mesh`` holds ``+c d_st'`` (``d_st = eps + D(s) - <D>``), whose part ``c eps'`` is in
        :meth:`mesh_force` and whose rest is ``dG/dt`` -- with its impulses ``c [D]`` where ``D``
        jumps (the rectangular ``D`` is piecewise constant: impulses only). Shape ``(ndof,) + s.shape``.
        """
        if self.coupling != "LTI":
            return None
        step = self.mesh_damping_Ns_per_m * self.normal_load_N * self.mesh.compliance_fluctuation(self, s, xp)
        return xp.stack([step] + [0.0 * step] * (self.ndof - 1))

    def lti_damping_impulse(self, s_jump, omega_pinion):
        """Generalised impulse [N s] at phase `s_jump`: the jump ``[G]`` of :meth:`lti_step_forcing`
        (zero unless LTI), which time integration applies as a velocity kick ``M dv = [G]``."""
        if self.coupling != "LTI":
            return np.zeros(self.ndof)
        sides = self.lti_step_forcing(np.asarray([s_jump - 1e-9, s_jump + 1e-9]) % 1.0)
        return np.asarray(sides[:, 1] - sides[:, 0], dtype=float)

    def phase_breakpoints(self) -> np.ndarray:
        """Mesh phases in [0, 1) where the equations switch (numpy; for time integration): pair
        entry and exit, pitch crossings and, per pair, relief starts and table nodes."""
        return self.mesh.phase_breakpoints(self)

    @property
    def pitch_point_m(self):
        """``x_P``: where nominal sliding vanishes, ``L Z_p / (Z_p + Z_g)`` [m]."""
        return self.line_of_action_m * self.teeth_pinion / (self.teeth_pinion + self.teeth_gear)

    def breakpoint_candidates(self, xp=np):
        """Phases where the equations may switch, traced-friendly (duplicates harmless)."""
        return self.mesh.breakpoints(self, xp)

    def static_state(self, omega_pinion, xp=np):
        """Quasi-static state ``(delta_s(s), u_s)`` about which the vibration is computed.

        ``delta_s`` of :meth:`static_dte` (``eps + N/k(s)``, + half the backlash) carries the static load;
        ``u_s`` [m] is the soft spring's wind-up that balances the mean output torque
        including the mean friction torques of the quasi-static state (MODEL.md section 4):
        ``k_u u_s = < T_p/R_bp + T_fp/R_bp + T_fg/R_bg - T_g/R_bg >``. Zero unless "spring".
        """
        from ..engine.quadrature import mesh_period_rule

        # the same nodes in numpy (read-outs, time integration) as in the compiled HB residual: with
        # relief the quasi-static pair loads have a kink between the breakpoints (a relieved pair
        # taking up load), where two layouts differ beyond rounding (~2e-7 of u_s), and the summary's
        # output power k_b (u + u_s) Omega_g R_bg would not balance the residual's
        s, w = mesh_period_rule(self.breakpoint_candidates(xp), 4, xp, same_nodes=True)
        delta = self.static_dte(s, omega_pinion, xp)
        if self.boundary != "spring":
            return delta, 0.0 * omega_pinion
        closed = self._closed_form_windup(omega_pinion, xp)
        if closed is not None:
            return delta, closed
        q = xp.stack([delta] + [0.0 * s] * (self.ndof - 1))
        force = self.generalized_force(s, q, 0.0 * q, omega_pinion, "all", 0.0, 0.0, xp)
        # remove the spring's own term (u = 0, u' = 0 -> it is zero) and average
        return delta, xp.sum(w * force[self.layout.index("u")]) / self.spring_stiffness_N_per_m

    def static_windup(self, omega_pinion, xp=np):
        """The soft spring's wind-up ``u_s`` [m] of :meth:`static_state` alone: zero unless
        "spring", in closed form for the sgn and atan laws (no quadrature rule, no static DTE),
        else by :meth:`static_state`'s quadrature. `omega_pinion` may be an array of speeds (a
        curve's read-outs): the closed form takes them at once, the quadrature one by one."""
        if self.boundary != "spring":
            return 0.0 * omega_pinion
        closed = self._closed_form_windup(omega_pinion, xp)
        if closed is not None:
            return closed
        if xp.ndim(omega_pinion) == 0:
            return self.static_state(omega_pinion, xp)[1]
        speeds = xp.reshape(xp.asarray(omega_pinion), (-1,))
        return xp.reshape(xp.stack([self.static_state(w, xp)[1] for w in speeds]), xp.shape(omega_pinion))

    def _closed_form_windup(self, omega_pinion, xp=np):
        """``k_u u_s = T_p / R_bp + < T_fp/R_bp + T_fg/R_bg >`` with the closed-form mean (``None``
        for laws without one)."""
        closed = self._mean_static_friction_force(omega_pinion, xp)
        if closed is None:
            return None
        return (self.torque_pinion_Nm / self.base_radius_pinion_m + closed) / self.spring_stiffness_N_per_m

    def _mean_static_friction_force(self, omega_pinion, xp=np):
        r"""``< T_fp/R_bp + T_fg/R_bg >`` [N] of the quasi-static state in closed form, for the
        laws of ``sgn(V_s)`` or ``atan(V_s/V_0)`` (``None`` for other laws: quadrature).

        At the quasi-static state the speeds are nominal and the pair loads ``sigma_j N`` (also in
        formulation B: ``F_mesh = N`` there), so on each piece of the period where the pairs in
        contact do not change, slot ``j`` contributes ``sigma_j N int (alpha + beta s) mu(gamma +
        delta s) ds``: the moment arm ``-xi_p/R_bp + xi_g/R_bg`` and the sliding velocity
        ``V_s = xi_p (W_p + W_g) - L W_g`` are affine in ``s``. With ``x = V_s / V_0``, ``A + B x``
        the arm, ``int (A + B x) atan x dx = A (x atan x - ln(1+x^2)/2) + B ((x^2+1) atan x - x)/2``;
        for ``sgn``, the integral of the arm changes sign where ``V_s`` does.
        """
        name = self.friction.name
        if name not in ("arctan", "coulomb", "none") or not self.mesh.equal_shares:
            return None
        if name == "none" or (self.coupling == "LTI" and self.lti_friction == "damping"):
            return 0.0 * omega_pinion
        wp, wg, _ = self.speeds(omega_pinion)
        # the three pieces on the last axis, (slot, from, to, load share): two pairs until
        # Gamma - 1, then slot 0 alone -- as arrays, so that the compiled residual evaluates them
        # in a few vector kernels instead of ~50 scalar ones
        wp, wg = xp.asarray(wp)[..., None], xp.asarray(wg)[..., None]
        rbp, rbg, pitch = self.base_radius_pinion_m, self.base_radius_gear_m, self.base_pitch_m
        slope = pitch * (wp + wg)  # d V_s / d s
        beta = -pitch * (1.0 / rbp + 1.0 / rbg)  # d arm / d s
        moving = xp.abs(slope) > 0
        slope_safe = xp.where(moving, slope, 1.0)
        g1 = self.contact_ratio - 1.0
        zero = 0.0 * g1
        lower, upper = xp.stack([zero, zero, g1]), xp.stack([g1, g1, zero + 1.0])
        slot, share = np.array([0.0, 1.0, 0.0]), np.array([0.5, 0.5, 1.0])
        xi0 = self.contact_start_m + pitch * slot  # xi_p at s = 0
        gamma = xi0 * (wp + wg) - self.line_of_action_m * wg
        alpha = self.line_of_action_m / rbg - xi0 * (1.0 / rbp + 1.0 / rbg)
        if name == "arctan":
            v0 = self.friction.v0
            big_a, big_b = alpha - beta * gamma / slope_safe, beta * v0 / slope_safe

            def antiderivative(s):
                x = (gamma + slope_safe * s) / v0
                at = xp.arctan(x)
                return big_a * (x * at - 0.5 * xp.log1p(x * x)) + big_b * 0.5 * ((x * x + 1.0) * at - x)

            piece = (2.0 * self.friction.mu0 / np.pi) * (v0 / slope_safe) * (antiderivative(upper) - antiderivative(lower))
        else:  # coulomb: sgn(gamma + slope s) = sgn(slope) sgn(s - s0)
            s0 = xp.clip(-gamma / slope_safe, lower, upper)

            def arm_integral(s):
                return alpha * s + 0.5 * beta * s * s

            piece = self.friction.mu0 * xp.sign(slope) * (arm_integral(upper) - 2.0 * arm_integral(s0) + arm_integral(lower))
        return xp.sum(share * self.normal_load_N * xp.where(moving, piece, 0.0), axis=-1)


# -- the assembly's arithmetic: structural zeros skipped, unit factors exact ---------------------
def _is_zero(c) -> bool:
    return isinstance(c, float) and c == 0.0


def _scaled(value, c):
    """``c value``, or ``None`` for a structural zero (``c`` a Python 0.0); +-1 exactly."""
    if isinstance(c, float):
        if c == 0.0:
            return None
        if c == 1.0:
            return value
        if c == -1.0:
            return -value
    return c * value


def _add(row, term):
    return term if row is None else row + term


def _apply(out, rows, forces: dict) -> None:
    """``out += P^T f`` for physical forces ``f`` (name -> array), in the order given."""
    for name, force in forces.items():
        for j, c in enumerate(rows[name]):
            term = _scaled(force, c)
            if term is not None:
                out[j] = _add(out[j], term)


def _combine(row, values):
    """``sum_j P_ij values[j]`` for one row of ``P`` (a physical rate from the generalised ones)."""
    total = None
    for j, c in enumerate(row):
        term = _scaled(values[j], c)
        if term is not None:
            total = _add(total, term)
    return total
