"""Config -> physics: build a :class:`~hbgear.gear.model.GearPairModel` from a ``RunConfig``.

Checks that need the physics (geometry, model combinations) raise
:class:`~hbgear.errors.ConfigError` naming the key, like the config loader does.
"""

from __future__ import annotations

import numpy as np

from .errors import ConfigError
from .gear.friction import LAWS, Arctan, Coulomb, KelleyLemanski, NoFriction
from .gear.geometry import GearPair
from .gear.model import GearPairModel

__all__ = ["build_geometry", "build_model", "friction_law"]


def build_geometry(gear, contact_ratio: float | None = None) -> GearPair:
    """``GearPair`` from ``[gear]``; `contact_ratio` overrides the config (maps, continuation)."""
    target = contact_ratio if contact_ratio is not None else gear.contact_ratio
    if target is not None:
        return GearPair.with_contact_ratio(
            gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad, float(target)
        )
    ha = 1.0 if gear.addendum_coefficient is None else gear.addendum_coefficient
    return GearPair(gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad, ha).check()


def friction_law(friction):
    """The friction law object of ``[friction]``."""
    if friction.law == "none" or friction.mu0 == 0.0 and friction.law in ("coulomb", "arctan"):
        return NoFriction()
    if friction.law == "coulomb":
        return Coulomb(friction.mu0)
    if friction.law == "arctan":
        return Arctan(friction.mu0, friction.v0_m_per_s)
    if friction.law == "kelley-lemanski":
        if friction.roughness_um >= 1.27:
            raise ConfigError("friction.roughness_um", friction.roughness_um, "a roughness below 1.27 um (Kelley-Lemanski)")
        return KelleyLemanski(friction.viscosity_Pa_s, friction.roughness_um)
    raise ConfigError("friction.law", friction.law, f"one of {sorted(LAWS)}")


def build_model(cfg, contact_ratio: float | None = None) -> GearPairModel:
    """The gear-pair model of a run config (SI throughout)."""
    geometry = build_geometry(cfg.gear, contact_ratio)
    mesh = cfg.mesh
    gamma = geometry.contact_ratio
    if mesh.k_min_N_per_m is not None:
        k_min = mesh.k_min_N_per_m
    else:
        # k_mean = k_max (Gamma-1) + k_min (2-Gamma) at the CONFIGURED contact ratio -> k_min;
        # k_max and k_min belong to the teeth and are held when the contact ratio is varied
        gamma_config = geometry.contact_ratio if contact_ratio is None else build_geometry(cfg.gear).contact_ratio
        k_min = (mesh.k_mean_N_per_m - mesh.k_max_N_per_m * (gamma_config - 1.0)) / (2.0 - gamma_config)
        if not (0.0 < k_min <= mesh.k_max_N_per_m):
            raise ConfigError(
                "mesh.k_mean_MN_per_m",
                mesh.k_mean_N_per_m / 1e6,
                f"a mean stiffness giving 0 < k_min <= k_max at contact ratio {gamma:.4f}",
            )
    law = friction_law(cfg.friction)
    fr = cfg.friction
    if fr.model == "NLTV" and law.discontinuous:
        # sgn(Vs) of the instantaneous sliding velocity is regularised (documented, shared by HB
        # and time integration): (2/pi) atan(Vs / v_reg)
        law = law.regularized(fr.regularization_m_per_s)
    coupling, formulation, boundary = fr.model, fr.formulation, cfg.boundary.output
    contact = "backlash" if mesh.backlash_m > 0 else "linear"
    if coupling == "LTI" and formulation == "B":
        raise ConfigError("friction.formulation", "B", "'A' with model 'LTI' (LTI uses quasi-static loads)")
    if coupling == "LTI" and contact == "backlash":
        raise ConfigError("mesh.backlash_um", mesh.backlash_m * 1e6, "0 with model 'LTI' (LTI is linear)")
    if coupling != "LTI" and fr.lti_friction != "excitation":
        raise ConfigError("friction.lti_friction", fr.lti_friction, "'excitation' unless friction.model is 'LTI'")
    if coupling == "NLTV" and boundary == "torques":
        raise ConfigError(
            "boundary.output",
            "torques",
            "'spring' or 'reaction' with model 'NLTV' (friction needs both gear speeds; with constant "
            "torques only the DTE is periodic)",
        )
    return GearPairModel(
        teeth_pinion=float(geometry.teeth_pinion),
        teeth_gear=float(geometry.teeth_gear),
        base_radius_pinion_m=geometry.base_radius_pinion_m,
        base_radius_gear_m=geometry.base_radius_gear_m,
        contact_start_m=geometry.contact_start_m,
        base_pitch_m=geometry.base_pitch_m,
        line_of_action_m=geometry.line_of_action_m,
        contact_ratio=gamma,
        inertia_pinion_kgm2=cfg.gear.inertia_pinion_kgm2,
        inertia_gear_kgm2=cfg.gear.inertia_gear_kgm2,
        k_max_N_per_m=mesh.k_max_N_per_m,
        k_min_N_per_m=k_min,
        damping_ratio=mesh.damping_ratio,
        backlash_m=mesh.backlash_m,
        ste_amplitude_m=np.asarray(mesh.ste_amplitude_m, dtype=float),
        ste_phase_rad=np.asarray(mesh.ste_phase_rad, dtype=float),
        torque_pinion_Nm=cfg.load.torque_pinion_Nm,
        friction=law,
        face_width_m=cfg.gear.face_width_m,
        spring_stiffness_ratio=cfg.boundary.stiffness_ratio,
        spring_damping_ratio=cfg.boundary.damping_ratio,
        coupling=coupling,
        formulation=formulation,
        boundary=boundary,
        damping_model=mesh.damping_model,
        contact=contact,
        lti_friction=fr.lti_friction,
    )
