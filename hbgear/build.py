"""Config -> physics: build a :class:`~hbgear.gear.model.GearPairModel` from a ``RunConfig``,
and the tooth-contact objects (geometry, pair stiffness, profile modification) of MODEL.md
section 9 with :func:`build_tooth_contact`.

Checks that need the physics (geometry, model combinations) raise
:class:`~hbgear.errors.ConfigError` naming the key, like the config loader does.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from .config import PAIR_DAMPING
from .errors import ConfigError
from .gear.contact import (
    Iso6336PairStiffness,
    Iso6336Stiffness,
    ProfileModification,
    RectangularMeshStiffness,
    load_pair_stiffness_table,
    potential_energy_pair_stiffness,
    profile_modification,
)
from .gear.geometry import GearPair
from .gear.kelley_lemanski import ROUGHNESS_CLIP_UIN, MICROINCH_PER_UM

__all__ = ["ToothContact", "build_bearings", "build_geometry", "build_model", "build_shafts", "build_pair_stiffness", "build_tooth_contact",
           "check_config", "friction_law", "model_at_contact_ratio"]

#: Largest Kelley-Lemanski roughness accepted [um]: where the roughness factor's guard starts.
ROUGHNESS_MAX_UM = ROUGHNESS_CLIP_UIN / MICROINCH_PER_UM

#: A working centre distance may sit this far [m] below the zero-backlash one (printed rounding).
CENTER_DISTANCE_ROUNDING_M = 0.5e-6

#: ``h_f = r_f / r_int`` range of Sainsot, Velex & Duverger's fillet-foundation fit.
FILLET_FIT_RANGE = (1.4, 7.0)


def build_geometry(gear, contact_ratio: float | None = None) -> GearPair:
    """``GearPair`` from ``[gear]``; `contact_ratio` overrides the config (maps, continuation).

    Unshifted pairs: exactly as before (the common addendum solved for a contact ratio, or
    given). Profile-shifted pairs: the given addendum, the shifts, the working centre distance
    (zero-backlash, or imposed and then not below it) and optional tip shortening (not where it
    would lengthen the tips); their contact ratio must lie in (1, 2).
    """
    target = contact_ratio if contact_ratio is not None else gear.contact_ratio
    if target is not None:
        if gear.shifted:  # the config rejects contact_ratio with shift; this is a map's override
            raise ConfigError("gear.profile_shift_pinion", gear.profile_shift_pinion,
                              "0 where the contact ratio is varied (the addendum is solved for unshifted pairs only)")
        return GearPair.with_contact_ratio(
            gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad, float(target)
        )
    ha = 1.0 if gear.addendum_coefficient is None else gear.addendum_coefficient
    if not gear.shifted:
        return GearPair(gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad, ha).check()
    pair = GearPair(gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad, ha,
                    gear.profile_shift_pinion, gear.profile_shift_gear, gear.working_center_distance_m,
                    gear.tip_shortening)
    _check_shifted(gear, pair)
    try:
        return pair.check()
    except ConfigError:
        raise ConfigError("gear.profile_shift_pinion", gear.profile_shift_pinion,
                          f"with profile_shift_gear = {gear.profile_shift_gear:g} and addendum_coefficient = {ha:g}, "
                          f"a shift giving {_invalid_geometry(pair)}") from None


def _invalid_geometry(pair: GearPair) -> str:
    """What :meth:`GearPair.check` found wrong with `pair`, in words."""
    if pair.tip_radius_pinion_m <= pair.base_radius_pinion_m or pair.tip_radius_gear_m <= pair.base_radius_gear_m:
        return "tips beyond the base circles"
    if pair.contact_start_m < 0 or pair.contact_end_m > pair.line_of_action_m:
        return ("contact inside the line of action (a tip reaches past the other gear's base-circle tangency: "
                f"x_A = {pair.contact_start_m * 1e3:.3f} mm, x_E = {pair.contact_end_m * 1e3:.3f} mm, "
                f"L = {pair.line_of_action_m * 1e3:.3f} mm)")
    return f"a contact ratio in (1, 2) (gives {pair.contact_ratio:.4f})"


def _check_shifted(gear, pair: GearPair) -> None:
    """An imposed ``a_w`` not below the zero-backlash one; tip shortening ``k = x1 + x2 - y >= 0``."""
    if gear.working_center_distance_m is not None:
        zero_backlash = GearPair(pair.teeth_pinion, pair.teeth_gear, pair.module_m, pair.pressure_angle_rad,
                                 pair.addendum_coefficient, pair.profile_shift_pinion,
                                 pair.profile_shift_gear).center_distance_m
        if gear.working_center_distance_m < zero_backlash - CENTER_DISTANCE_ROUNDING_M:
            raise ConfigError("gear.center_distance_mm", gear.working_center_distance_m * 1e3,
                              f"a working centre distance >= {zero_backlash * 1e3:.4f} mm, the zero-backlash distance "
                              "of these profile shifts (a smaller one makes the teeth interfere)")
    if gear.tip_shortening and pair.tip_shortening_coefficient < 0.0:
        raise ConfigError("gear.tip_shortening", True,
                          f"false here: x1 + x2 - y = {pair.tip_shortening_coefficient:.4f} < 0 would lengthen the "
                          "tips")


def friction_law(friction):
    """The friction law object of ``[friction]``."""
    from .gear.friction import LAWS, Arctan, Coulomb, KelleyLemanski, NoFriction

    if friction.law == "none" or friction.mu0 == 0.0 and friction.law in ("coulomb", "arctan"):
        return NoFriction()
    if friction.law == "coulomb":
        return Coulomb(friction.mu0)
    if friction.law == "arctan":
        return Arctan(friction.mu0, friction.v0_m_per_s)
    if friction.law == "kelley-lemanski":
        return KelleyLemanski(friction.viscosity_Pa_s, friction.roughness_um)
    raise ConfigError("friction.law", friction.law, f"one of {sorted(LAWS)}")


def _k_min(cfg, geometry: GearPair, contact_ratio: float | None = None) -> float:
    """``k_min`` [N/m] of the rectangular model: given, or from ``k_mean`` at the configured Gamma."""
    mesh = cfg.mesh
    if mesh.k_min_N_per_m is not None:
        return mesh.k_min_N_per_m
    # k_mean = k_max (Gamma-1) + k_min (2-Gamma) at the CONFIGURED contact ratio -> k_min;
    # k_max and k_min belong to the teeth and are held when the contact ratio is varied
    gamma_config = geometry.contact_ratio if contact_ratio is None else build_geometry(cfg.gear).contact_ratio
    k_min = (mesh.k_mean_N_per_m - mesh.k_max_N_per_m * (gamma_config - 1.0)) / (2.0 - gamma_config)
    if not (0.0 < k_min <= mesh.k_max_N_per_m):
        raise ConfigError(
            "mesh.k_mean_MN_per_m",
            mesh.k_mean_N_per_m / 1e6,
            f"a mean stiffness giving 0 < k_min <= k_max at contact ratio {geometry.contact_ratio:.4f}",
        )
    return k_min


def check_config(cfg, contact_ratio: float | None = None) -> tuple[GearPair, float | None]:
    """The physics checks of a run config for the dynamic model that need the geometry but no JAX
    (so a bad input ends at once, before anything heavy is imported): the contact ratio in (1, 2),
    a mean stiffness giving ``0 < k_min <= k_max`` (rectangular), or the per-pair tooth contact
    (:func:`build_tooth_contact`: the table, the reliefs against the path of contact, the bores;
    proportional damping), the coupling/formulation/boundary/backlash combinations, the
    Kelley-Lemanski roughness limit.

    **Returns:** ``(geometry, k_min [N/m])``, ``k_min = None`` for a per-pair model.
    **Raises:** :class:`~hbgear.errors.ConfigError`.
    """
    mesh, fr = cfg.mesh, cfg.friction
    geometry = build_geometry(cfg.gear, contact_ratio)
    if mesh.stiffness_model == "rectangular":
        k_min = _k_min(cfg, geometry, contact_ratio)
    else:
        if mesh.damping_model != "proportional":
            raise ConfigError("mesh.damping_model", mesh.damping_model, PAIR_DAMPING)
        build_tooth_contact(cfg, geometry=geometry)
        k_min = None
    if fr.law == "kelley-lemanski" and fr.roughness_um > ROUGHNESS_MAX_UM:
        # C_R = 50/(50 - S) is held at S = 45 uin (C_R = 10) as a guard: above it the law would be
        # silently clipped, so such a roughness is refused instead
        raise ConfigError("friction.roughness_um", fr.roughness_um,
                          f"a roughness <= {ROUGHNESS_MAX_UM:.4g} um for Kelley-Lemanski (C_R = 50/(50 - S) <= 10; "
                          "it diverges at 1.27 um)")
    coupling, formulation, boundary = fr.model, fr.formulation, cfg.boundary.output
    if coupling == "LTI" and formulation == "B":
        raise ConfigError("friction.formulation", "B", "'A' with model 'LTI' (LTI uses quasi-static loads)")
    if coupling == "LTI" and mesh.stiffness_model != "rectangular":
        # LTI's excitation is the loaded static TE; per pair its deflection D(s) varies between the
        # breakpoints, whose damping term c dD/dt time integration does not carry (only its jumps)
        raise ConfigError("friction.model", "LTI", "'LTV' or 'NLTV' with a per-pair stiffness_model")
    if coupling == "LTI" and mesh.backlash_m > 0:
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
    return geometry, k_min


def build_model(cfg, contact_ratio: float | None = None):
    """The gear-pair model of a run config (SI throughout); :func:`check_config` first. A per-pair
    ``stiffness_model`` gives the model a :class:`~hbgear.gear.mesh.PairContactMesh`
    (:func:`_with_pair_contact`)."""
    from .gear.model import GearPairModel

    geometry, k_min = check_config(cfg, contact_ratio)
    mesh, fr = cfg.mesh, cfg.friction
    gamma = geometry.contact_ratio
    law = friction_law(fr)
    if fr.model == "NLTV" and law.discontinuous:
        # sgn(Vs) of the instantaneous sliding velocity is regularised (documented, shared by HB
        # and time integration): (2/pi) atan(Vs / v_reg)
        law = law.regularized(fr.regularization_m_per_s)
    coupling, formulation, boundary = fr.model, fr.formulation, cfg.boundary.output
    contact = "backlash" if mesh.backlash_m > 0 else "linear"
    model = GearPairModel(
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
        k_max_N_per_m=mesh.k_max_N_per_m if k_min is not None else math.nan,
        k_min_N_per_m=k_min if k_min is not None else math.nan,
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
        bearings=build_bearings(cfg),
        shafts=build_shafts(cfg),
    )
    return model if k_min is not None else _with_pair_contact(model, build_tooth_contact(cfg, geometry=geometry))


def _with_pair_contact(model, contact: ToothContact):
    """`model` with the per-pair mesh of `contact` (MODEL.md section 9); its ``k_max``, ``k_min``
    fields become the extremes of ``k(s) = sum_j k_pair(xi_j)`` over the mesh period (information)."""
    from .engine.quadrature import mesh_period_rule
    from .gear.mesh import PairContactMesh

    mesh = PairContactMesh.build(contact.pair_stiffness, contact.modification, model)
    s, _ = mesh_period_rule(mesh.phase_breakpoints(model), 64)
    k = mesh.stiffness(model, np.concatenate([s, mesh.phase_breakpoints(model)]))
    return model.replace(mesh=mesh, k_max_N_per_m=float(np.max(k)), k_min_N_per_m=float(np.min(k)))


def build_bearings(cfg):
    """:class:`~hbgear.gear.dofs.Bearings` of ``[bearings]`` (``None`` without the section: rigid)."""
    from .gear.dofs import Bearings

    b = cfg.bearings
    if b is None:
        return None
    mass_pinion, mass_gear = b.masses(cfg.gear)
    return Bearings(mass_pinion_kg=mass_pinion, mass_gear_kg=mass_gear,
                    k_pinion_loa_N_per_m=b.stiffness("pinion", "loa"), k_pinion_oloa_N_per_m=b.stiffness("pinion", "oloa"),
                    k_gear_loa_N_per_m=b.stiffness("gear", "loa"), k_gear_oloa_N_per_m=b.stiffness("gear", "oloa"),
                    damping_ratio=b.damping_ratio)


def build_shafts(cfg):
    """:class:`~hbgear.gear.dofs.Shafts` of ``[shafts]`` (``None`` without the section)."""
    from .gear.dofs import Shafts

    sh = cfg.shafts
    if sh is None:
        return None
    return Shafts(inertia_drive_kgm2=sh.drive_inertia_kgm2, inertia_load_kgm2=sh.load_inertia_kgm2,
                  stiffness_drive_Nm_per_rad=sh.drive_stiffness_Nm_per_rad,
                  stiffness_load_Nm_per_rad=sh.load_stiffness_Nm_per_rad,
                  damping_ratio_drive=sh.damping_ratio, damping_ratio_load=sh.damping_ratio)


def model_at_contact_ratio(cfg, contact_ratio: float):
    """The config's model at another contact ratio: ``k_max``, ``k_min`` held (they belong to the
    teeth), ``k_mean`` follows (MODEL.md section 2)."""
    return build_model(cfg, contact_ratio=float(contact_ratio))


class ToothContact(NamedTuple):
    """The tooth-contact objects of a config (MODEL.md section 9), SI.

    **Fields:** `geometry` (:class:`GearPair`); `pair_stiffness` (a single-pair model with
    ``stiffness(xi, xp)``, or :class:`RectangularMeshStiffness` for "rectangular"); `modification`
    (:class:`ProfileModification`, zero without [profile] relief); `iso6336` (the ISO 6336 numbers,
    for "iso6336" only, else `None`); `torque_pinion_Nm` (the torque the stiffness was built for).
    """

    geometry: GearPair
    pair_stiffness: Any
    modification: ProfileModification
    iso6336: Iso6336Stiffness | None
    torque_pinion_Nm: float


def build_tooth_contact(cfg, torque_pinion_Nm: float | None = None, geometry: GearPair | None = None) -> ToothContact:
    """Geometry, pair stiffness and profile modification of a config, every input checked.

    `torque_pinion_Nm` (default ``[load] torque_pinion_Nm``) matters only for ISO 6336's low
    line-load factor; `geometry` reuses an already built :func:`build_geometry`.

    **Raises:** :class:`~hbgear.errors.ConfigError` naming the key (a bad table, a relief
    longer than the path of contact, a bore outside the fillet fit, ...).
    """
    torque = cfg.load.torque_pinion_Nm if torque_pinion_Nm is None else float(torque_pinion_Nm)
    geometry = build_geometry(cfg.gear) if geometry is None else geometry
    stiffness, numbers = build_pair_stiffness(cfg, geometry, torque)
    modification = profile_modification(geometry, **cfg.profile.to_keys())
    return ToothContact(geometry, stiffness, modification, numbers, torque)


def build_pair_stiffness(cfg, geometry: GearPair, torque_pinion_Nm: float) -> tuple[Any, Iso6336Stiffness | None]:
    """The pair stiffness of ``[mesh] stiffness_model`` and, for "iso6336", its ISO numbers.

    - "rectangular": ``k_max`` and ``k_min`` (:class:`RectangularMeshStiffness`).
    - "pair_table": the CSV of ``mesh.pair_stiffness_file`` (checked by its loader).
    - "iso6336": ``c'`` and ``c_gamma_alpha`` of the pair (same modulus and rack on both gears) at
      the line load ``w = F_t / b``, ``F_t = T_p / r_p`` (application factor ``K_A = 1``: the
      torque analysed), spread by the documented parabola.
    - "potential_energy": from the tooth geometry, the material and the bores.
    """
    mesh, b = cfg.mesh, cfg.gear.face_width_m
    model = mesh.stiffness_model
    if model == "rectangular":
        return RectangularMeshStiffness(mesh.k_max_N_per_m, _k_min(cfg, geometry)), None
    if model == "pair_table":
        return load_pair_stiffness_table(mesh.pair_stiffness_file, geometry), None
    if model == "iso6336":
        line_load = torque_pinion_Nm / geometry.pitch_radius_pinion_m / (b * 1e3)
        return Iso6336PairStiffness.from_geometry(
            geometry, b, rack_dedendum_coefficient=(mesh.rack_dedendum_coefficient,) * 2,
            blank_factor=mesh.blank_factor, youngs_modulus_Pa=(mesh.youngs_modulus_Pa,) * 2,
            line_load_N_per_mm=line_load)
    bores = _potential_energy_bores(cfg, geometry)
    return potential_energy_pair_stiffness(
        geometry, b, mesh.youngs_modulus_Pa, mesh.poisson_ratio, bores,
        rack_dedendum_coefficient=mesh.rack_dedendum_coefficient,
        rack_tip_radius_coefficient=mesh.rack_tip_radius_coefficient), None


def _potential_energy_bores(cfg, geometry: GearPair) -> tuple[float, float]:
    """Bore radii ``(r_int,p, r_int,g)`` [m], after checking what the potential-energy model assumes.

    The basic rack keeps a tip flat (``e = m [pi/4 - h tan(phi) - rho (1 - sin phi)/cos phi] > 0``);
    each root circle ``r_f = m (z/2 - h + x)`` lies inside the base circle (the Yang-Lin tooth
    starts there); ``h_f = r_f / r_int`` is inside :data:`FILLET_FIT_RANGE`.
    """
    mesh, phi = cfg.mesh, geometry.pressure_angle_rad
    h, rho = mesh.rack_dedendum_coefficient, mesh.rack_tip_radius_coefficient
    rho_max = (math.pi / 4 - h * math.tan(phi)) * math.cos(phi) / (1 - math.sin(phi))
    if rho >= rho_max:
        raise ConfigError("mesh.rack_tip_radius_coefficient", rho,
                          f"a value < {rho_max:.4f} with rack_dedendum_coefficient = {h:g} (the rack needs a tip flat)")
    bores = []
    for end, teeth, shift, base in (
        ("pinion", geometry.teeth_pinion, geometry.profile_shift_pinion, geometry.base_radius_pinion_m),
        ("gear", geometry.teeth_gear, geometry.profile_shift_gear, geometry.base_radius_gear_m),
    ):
        root = geometry.module_m * (teeth / 2 - h + shift)
        if root >= base:
            raise ConfigError("mesh.stiffness_model", "potential_energy",
                              f"a pair whose root circles lie inside their base circles (the {end}'s root diameter "
                              f"{2e3 * root:.3f} mm >= base diameter {2e3 * base:.3f} mm; the Yang-Lin tooth starts at "
                              "the base circle): use 'iso6336' or 'pair_table'")
        bore = getattr(cfg.gear, f"bore_diameter_{end}_m") / 2
        lo, hi = FILLET_FIT_RANGE
        if not lo <= root / bore <= hi:
            raise ConfigError(f"gear.bore_diameter_{end}_mm", 2e3 * bore,
                              f"a bore diameter in [{2e3 * root / hi:.3f}, {2e3 * root / lo:.3f}] mm (root radius / "
                              f"bore radius in [{lo:g}, {hi:g}], the range of the fillet-foundation fit; root diameter "
                              f"{2e3 * root:.3f} mm)")
        bores.append(bore)
    return bores[0], bores[1]
