"""TOML run configuration -> frozen, typed, validated dataclasses in SI units.

The TOML file uses engineering units spelled out in the key names (`module_mm`,
`k_max_MN_per_m`, `backlash_um`, `pressure_angle_deg`, ...); everything stored in the
dataclasses below is SI (m, N/m, rad, kg m^2, N m, s) and the field names say so.

Every value is checked when the file is read: its type (an integer is not a float where an
integer is required; a boolean is never a number), that it is finite, its range, allowed
names, mutually exclusive keys, and unknown sections or keys (the message lists the allowed
ones). Any problem raises :class:`hbgear.errors.ConfigError` with the dotted key, the value
given and what is allowed. Checks that need the gear geometry (e.g. the contact ratio that an
`addendum_coefficient` produces, a relief length against the path of contact, the contents of
`mesh.pair_stiffness_file`) belong to the physics code (:mod:`hbgear.build`).

**Public API:** :func:`load_config`, :func:`read_toml`, :func:`parse_config`, :func:`apply_overrides`,
:class:`RunConfig` (with :meth:`RunConfig.to_dict`) and the section dataclasses.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import re
import tomllib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from .errors import ConfigError

__all__ = [
    "BoundaryConfig",
    "FrictionConfig",
    "GearConfig",
    "LoadConfig",
    "MapConfig",
    "MeshConfig",
    "ProfileConfig",
    "RunConfig",
    "SimulateConfig",
    "SolverConfig",
    "StudyConfig",
    "StudyParameter",
    "SweepConfig",
    "apply_overrides",
    "load_config",
    "parse_config",
    "read_toml",
]

MAX_TEETH = 10_000
MAX_HARMONICS = 2048
MAX_TIME_SAMPLES = 1 << 20
MAX_COUNT = 10_000_000  # cap on point / cycle / iteration counts (guards against typos)

FRICTION_LAWS = ("none", "coulomb", "arctan", "kelley-lemanski")
FRICTION_FORMULATIONS = ("A", "B")
FRICTION_MODELS = ("LTI", "LTV", "NLTV")
LTI_FRICTION = ("excitation", "damping", "both")
DAMPING_MODELS = ("constant", "proportional")
BOUNDARY_OUTPUTS = ("torques", "spring", "reaction")
STIFFNESS_MODELS = ("rectangular", "pair_table", "iso6336", "potential_energy")
PROFILE_SHAPES = ("linear", "parabolic")

#: What a per-pair `stiffness_model` allows for [mesh] damping_model (MODEL.md section 9).
PAIR_DAMPING = ("'proportional' (the default) with a per-pair stiffness_model: each pair's damper is "
                "c k_j / k_mean (MODEL.md section 9)")

#: The [mesh] stiffness keys each `stiffness_model` takes (any other one of them is an error).
MODEL_KEYS = {
    "rectangular": ("k_max_MN_per_m", "k_mean_MN_per_m", "k_min_MN_per_m"),
    "pair_table": ("pair_stiffness_file",),
    "iso6336": ("youngs_modulus_GPa", "rack_dedendum_coefficient", "blank_factor"),
    "potential_energy": ("youngs_modulus_GPa", "poisson_ratio", "rack_dedendum_coefficient",
                         "rack_tip_radius_coefficient"),
}

STUDY_KINDS = ("grid", "monte_carlo")
STUDY_DISTRIBUTIONS = ("normal", "uniform", "lognormal", "choice")
MAX_STUDY_SAMPLES = 1_000_000


# ----------------------------------------------------------------------------- dataclasses


@dataclass(frozen=True, kw_only=True)
class GearConfig:
    """Spur-gear pair geometry and inertias.

    **Fields:** `teeth_pinion`, `teeth_gear` [-]; `module_m` [m]; `pressure_angle_rad` [rad];
    `contact_ratio` [-] (target profile contact ratio, or `None`) XOR `addendum_coefficient`
    [-] (same on both gears; 1.0 when neither is given); `face_width_m` [m];
    `inertia_pinion_kgm2`, `inertia_gear_kgm2` [kg m^2]; `profile_shift_pinion`,
    `profile_shift_gear` [-] (``x_1``, ``x_2``); `working_center_distance_m` [m] (an imposed
    ``a_w`` of a profile-shifted pair, or `None` for its zero-backlash distance);
    `tip_shortening` (shorten both tips by ``(x_1 + x_2 - y) m``); `bore_diameter_pinion_m`,
    `bore_diameter_gear_m` [m] (the blanks' bores, for the potential-energy stiffness).

    The common addendum is solved for `contact_ratio` only for unshifted pairs at the reference
    centre distance, so `contact_ratio` excludes profile shift.
    """

    teeth_pinion: int
    teeth_gear: int
    module_m: float
    pressure_angle_rad: float = math.radians(20.0)
    contact_ratio: float | None = None
    addendum_coefficient: float | None = None
    face_width_m: float = 0.020
    inertia_pinion_kgm2: float
    inertia_gear_kgm2: float
    profile_shift_pinion: float = 0.0
    profile_shift_gear: float = 0.0
    working_center_distance_m: float | None = None
    tip_shortening: bool = False
    bore_diameter_pinion_m: float | None = None
    bore_diameter_gear_m: float | None = None

    @property
    def shifted(self) -> bool:
        """Whether either gear is profile-shifted."""
        return self.profile_shift_pinion != 0.0 or self.profile_shift_gear != 0.0

    def __post_init__(self):
        if self.shifted and self.contact_ratio is not None:
            raise ConfigError(
                "gear.contact_ratio",
                self.contact_ratio,
                "not with profile shift: give gear.addendum_coefficient (the contact ratio follows from the "
                "shifted geometry)",
            )
        if self.working_center_distance_m is not None and not self.shifted:
            raise ConfigError(
                "gear.center_distance_mm",
                self.working_center_distance_m * 1e3,
                "give gear.module_mm or gear.center_distance_mm, not both (both only for a profile-shifted "
                "pair, where center_distance_mm is the working centre distance)",
            )
        if self.contact_ratio is not None and self.addendum_coefficient is not None:
            raise ConfigError(
                "gear.addendum_coefficient",
                self.addendum_coefficient,
                "give gear.contact_ratio or gear.addendum_coefficient, not both",
            )
        if self.contact_ratio is None and self.addendum_coefficient is None:
            object.__setattr__(self, "addendum_coefficient", 1.0)


@dataclass(frozen=True, kw_only=True)
class MeshConfig:
    """Mesh stiffness, damping, backlash and unloaded static transmission error.

    **Fields:** `stiffness_model` (:data:`STIFFNESS_MODELS`); for "rectangular" (the paper's
    ``k(t)``): `k_max_N_per_m` [N/m] (two pairs in contact) and `k_mean_N_per_m` XOR
    `k_min_N_per_m` [N/m] (the other follows from the contact ratio); for "pair_table":
    `pair_stiffness_file` (a CSV of single-pair stiffness along the path); for "iso6336" and
    "potential_energy": `youngs_modulus_Pa` [Pa] (both gears), `rack_dedendum_coefficient`
    ``h_fP/m`` [-] of the basic rack, and `blank_factor` ``C_R`` [-] (iso6336), or
    `poisson_ratio` [-] and `rack_tip_radius_coefficient` ``rho_fP/m`` [-] (potential_energy);
    `damping_ratio` [-]; `damping_model` ("constant" or "proportional" to k(t); a per-pair
    model damps each pair in proportion to its stiffness, "proportional", its default); `backlash_m`
    [m] (total); `ste_amplitude_m` [m] and `ste_phase_rad` [rad], one entry per mesh order 1, 2.
    Defaults of the material and rack: steel (206 GPa, 0.3) and the ISO 53 profile A rack
    (``h_fP = 1.25 m``, ``rho_fP = 0.38 m``); solid blanks (``C_R = 1``).
    """

    stiffness_model: str = "rectangular"
    k_max_N_per_m: float | None = None
    k_mean_N_per_m: float | None = None
    k_min_N_per_m: float | None = None
    pair_stiffness_file: Path | None = None
    youngs_modulus_Pa: float = 206e9
    poisson_ratio: float = 0.3
    rack_dedendum_coefficient: float = 1.25
    rack_tip_radius_coefficient: float = 0.38
    blank_factor: float = 1.0
    damping_ratio: float = 0.01
    damping_model: str = "constant"
    backlash_m: float = 0.0
    ste_amplitude_m: tuple[float, ...] = ()
    ste_phase_rad: tuple[float, ...] = ()

    def __post_init__(self):
        if self.stiffness_model not in STIFFNESS_MODELS:
            raise ConfigError("mesh.stiffness_model", self.stiffness_model,
                              "one of " + ", ".join(repr(m) for m in STIFFNESS_MODELS))
        if len(self.ste_phase_rad) != len(self.ste_amplitude_m):
            raise ConfigError(
                "mesh.ste_phase_deg",
                list(self.ste_phase_rad),
                "a list of the same length as mesh.ste_amplitude_um "
                f"({len(self.ste_amplitude_m)})",
            )
        model = self.stiffness_model
        stiffnesses = {"k_max_MN_per_m": self.k_max_N_per_m, "k_mean_MN_per_m": self.k_mean_N_per_m,
                       "k_min_MN_per_m": self.k_min_N_per_m, "pair_stiffness_file": self.pair_stiffness_file}
        for name, value in stiffnesses.items():
            if value is not None and name not in MODEL_KEYS[model]:
                raise _inapplicable(f"mesh.{name}", value if name == "pair_stiffness_file" else value * 1e-6, model)
        if model == "pair_table" and self.pair_stiffness_file is None:
            raise ConfigError("mesh.pair_stiffness_file", _MISSING, "required with mesh.stiffness_model = 'pair_table'")
        if model != "rectangular":
            return
        if self.k_max_N_per_m is None:
            raise ConfigError("mesh.k_max_MN_per_m", _MISSING,
                              "required with mesh.stiffness_model = 'rectangular' (the default)")
        if (self.k_mean_N_per_m is None) == (self.k_min_N_per_m is None):
            raise ConfigError(
                "mesh.k_mean_MN_per_m",
                self.k_mean_N_per_m,
                "give exactly one of mesh.k_mean_MN_per_m and mesh.k_min_MN_per_m",
            )


@dataclass(frozen=True, kw_only=True)
class LoadConfig:
    """Static load. **Fields:** `torque_pinion_Nm` [N m], input torque on the pinion."""

    torque_pinion_Nm: float


@dataclass(frozen=True, kw_only=True)
class ProfileConfig:
    """Tip and root relief of both flanks, along the line of action (MODEL.md section 9).

    **Fields:** `<flank>_<end>_relief_m` [m] (amount, material removed) and
    `<flank>_<end>_relief_length_m` [m] (from that end of the flank's active profile), for
    flank pinion | gear and end tip | root; `shape` ("linear" or "parabolic"). A relief amount
    needs a length > 0. The lengths are checked against the path of contact when the geometry
    is built (:func:`hbgear.gear.contact.profile_modification`).
    """

    pinion_tip_relief_m: float = 0.0
    pinion_tip_relief_length_m: float = 0.0
    gear_tip_relief_m: float = 0.0
    gear_tip_relief_length_m: float = 0.0
    pinion_root_relief_m: float = 0.0
    pinion_root_relief_length_m: float = 0.0
    gear_root_relief_m: float = 0.0
    gear_root_relief_length_m: float = 0.0
    shape: str = "linear"

    def __post_init__(self):
        for name in _RELIEFS:
            amount, length = getattr(self, f"{name}_m"), getattr(self, f"{name}_length_m")
            if amount > 0.0 and length == 0.0:
                raise ConfigError(f"profile.{name}_length_mm", 0.0,
                                  f"a length > 0 where profile.{name}_um = {amount * 1e6:g} > 0")

    @property
    def relieved(self) -> tuple[str, ...]:
        """The TOML keys of the non-zero relief amounts."""
        return tuple(f"{name}_um" for name in _RELIEFS if getattr(self, f"{name}_m") > 0.0)

    def to_keys(self) -> dict[str, Any]:
        """The [profile] table in its TOML keys and units (what ``profile_modification`` takes)."""
        keys: dict[str, Any] = {}
        for name in _RELIEFS:
            keys[f"{name}_um"] = getattr(self, f"{name}_m") * 1e6
            keys[f"{name}_length_mm"] = getattr(self, f"{name}_length_m") * 1e3
        return keys | {"shape": self.shape}


_RELIEFS = tuple(f"{flank}_{end}_relief" for end in ("tip", "root") for flank in ("pinion", "gear"))


@dataclass(frozen=True, kw_only=True)
class FrictionConfig:
    """Sliding friction at the teeth.

    **Fields:** `law` (none | coulomb | arctan | kelley-lemanski); `mu0` [-]; `v0_m_per_s`
    [m/s] (arctan smoothing speed); `formulation` ("A": quasi-static load, "B": dynamic mesh
    force); `model` (LTI | LTV | NLTV); `viscosity_Pa_s` [Pa s] and `roughness_um` [um, Rq]
    (kelley-lemanski only; roughness kept in micrometres as the law's constants use it);
    `regularization_m_per_s` [m/s]: with model NLTV, a discontinuous law (coulomb,
    kelley-lemanski) has ``sgn(Vs)`` replaced by ``(2/pi) atan(Vs / v_reg)`` -- the same in
    harmonic balance and time integration (results converge as it shrinks); `lti_friction`
    (model LTI only): "excitation" (nominal friction torques as a Fourier excitation, Eq. 10),
    "damping" (an energy-equivalent viscous damper at the mesh instead) or "both".
    """

    law: str = "coulomb"
    mu0: float = 0.1
    v0_m_per_s: float = 0.01
    formulation: str = "A"
    model: str = "LTV"
    viscosity_Pa_s: float = 0.01
    roughness_um: float = 0.5
    regularization_m_per_s: float = 0.005
    lti_friction: str = "excitation"


@dataclass(frozen=True, kw_only=True)
class BoundaryConfig:
    """Output boundary condition.

    **Fields:** `output` (torques | spring | reaction); `stiffness_ratio` [-]
    (k_mean Rbg^2 / kb for "spring"); `damping_ratio` [-] of the soft spring's own mode.
    """

    output: str = "spring"
    stiffness_ratio: float = 5e5
    damping_ratio: float = 0.0


#: Bearing directions: along (``loa``, ``y``) and across (``oloa``, ``x``) the line of action.
BEARING_DIRECTIONS = ("loa", "oloa")


@dataclass(frozen=True, kw_only=True)
class BearingsConfig:
    """Centre translations on bearings (MODEL.md section 10); the section present = 6 DOF.

    **Fields:** `<gear>_stiffness_N_per_m` [N/m] for both directions of the pinion / gear, and
    `<gear>_<direction>_stiffness_N_per_m` overriding one direction (``loa`` | ``oloa``);
    `damping_ratio` [-] (each direction ``c = 2 zeta sqrt(k m)``); `mass_pinion_kg`, `mass_gear_kg`
    [kg] (``None``: a solid disk, ``m = 2 J / r_pitch^2``, see :meth:`masses`). Every direction needs
    a stiffness (checked here).
    """

    pinion_stiffness_N_per_m: float | None = None
    gear_stiffness_N_per_m: float | None = None
    pinion_loa_stiffness_N_per_m: float | None = None
    pinion_oloa_stiffness_N_per_m: float | None = None
    gear_loa_stiffness_N_per_m: float | None = None
    gear_oloa_stiffness_N_per_m: float | None = None
    damping_ratio: float = 0.02
    mass_pinion_kg: float | None = None
    mass_gear_kg: float | None = None

    def __post_init__(self):
        for end in ("pinion", "gear"):
            for direction in BEARING_DIRECTIONS:
                if self.stiffness(end, direction) is None:
                    raise ConfigError(f"bearings.{end}_stiffness_MN_per_m", _MISSING,
                                      f"required: a positive stiffness in MN/m (both directions), unless "
                                      f"bearings.{end}_loa_stiffness_MN_per_m and bearings.{end}_oloa_stiffness_MN_per_m "
                                      "are both given")

    def stiffness(self, end: str, direction: str) -> float | None:
        """The stiffness [N/m] of `end` (pinion | gear) in `direction` (loa | oloa)."""
        own = getattr(self, f"{end}_{direction}_stiffness_N_per_m")
        return own if own is not None else getattr(self, f"{end}_stiffness_N_per_m")

    def masses(self, gear: GearConfig) -> tuple[float, float]:
        """``(m_p, m_g)`` [kg]: given, or solid disks ``m = 2 J / r_pitch^2`` (``r = m_n Z / 2``)."""
        out = []
        for end, teeth in (("pinion", gear.teeth_pinion), ("gear", gear.teeth_gear)):
            given = getattr(self, f"mass_{end}_kg")
            radius = gear.module_m * teeth / 2
            out.append(given if given is not None else 2.0 * getattr(gear, f"inertia_{end}_kgm2") / radius**2)
        return out[0], out[1]


@dataclass(frozen=True, kw_only=True)
class ShaftsConfig:
    """Torsional shafts to a drive and a load inertia (with [bearings]: the 8-DOF model).

    **Fields:** `drive_inertia_kgm2`, `load_inertia_kgm2` [kg m^2] (the input torque acts on the
    drive inertia, the output boundary on the load inertia); `drive_stiffness_Nm_per_rad`,
    `load_stiffness_Nm_per_rad` [N m/rad] (drive -- pinion, gear -- load); `damping_ratio` [-]
    of each shaft's own two-inertia mode.
    """

    drive_inertia_kgm2: float
    load_inertia_kgm2: float
    drive_stiffness_Nm_per_rad: float
    load_stiffness_Nm_per_rad: float
    damping_ratio: float = 0.02


@dataclass(frozen=True, kw_only=True)
class SolverConfig:
    """Harmonic-balance options.

    **Fields:** `harmonics` H [-] (`None` = "auto", grown until the top harmonics are
    negligible); `subharmonic` nu (1 or 2); `time_samples` per base period [-];
    `tolerance` [-] (relative residual); `max_iterations` [-] per Newton solve.
    """

    harmonics: int | None = 24
    subharmonic: int = 1
    time_samples: int = 1024
    tolerance: float = 1e-9
    max_iterations: int = 50

    def __post_init__(self):
        if self.harmonics is not None:
            need = 2 * self.harmonics * self.subharmonic + 2
            if self.time_samples < need:
                raise ConfigError(
                    "solver.time_samples",
                    self.time_samples,
                    f"an integer >= 2*harmonics*subharmonic+2 = {need} "
                    f"(harmonics = {self.harmonics}, subharmonic = {self.subharmonic})",
                )


@dataclass(frozen=True, kw_only=True)
class SimulateConfig:
    """Time-integration options.

    **Fields:** `cycles` [-] (maximum mesh cycles to integrate); `rtol` [-]; `atol_m` [m]
    (absolute tolerance on displacements); `steady_tolerance` [-] (relative change of the DTE
    waveform between successive periods that counts as steady state).
    """

    cycles: int = 400
    rtol: float = 1e-9
    atol_m: float = 1e-15
    steady_tolerance: float = 1e-6


@dataclass(frozen=True, kw_only=True)
class SweepConfig:
    """Frequency-response sweep for `frc`.

    **Fields:** `speed_rpm_start`, `speed_rpm_stop` [rpm] (either may be larger);
    `max_points` [-]; `step_rpm` [rpm] (initial continuation step, or `None` for automatic);
    `period_doubling`: follow the nu = 2 branch at each period doubling -- ``True``, ``False`` or
    ``None`` for "auto" (only where the nu = 2 problem is small; crossings are always located);
    `orders`: mesh orders 1..K in orders.csv (`None`: min(H / nu, 10)).
    """

    speed_rpm_start: float = 1000.0
    speed_rpm_stop: float = 20000.0
    max_points: int = 4000
    step_rpm: float | None = None
    period_doubling: bool | None = None
    orders: int | None = None

    def __post_init__(self):
        if self.speed_rpm_start == self.speed_rpm_stop:
            raise ConfigError(
                "sweep.speed_rpm_stop",
                self.speed_rpm_stop,
                f"a speed different from sweep.speed_rpm_start = {self.speed_rpm_start:g}",
            )


@dataclass(frozen=True, kw_only=True)
class MapConfig:
    """Stability-map grid (speed x contact ratio; k_max and k_min held as the ratio varies).

    **Fields:** `speed_rpm_start`, `speed_rpm_stop` [rpm], `speed_steps` [-];
    `contact_ratio_start`, `contact_ratio_stop` [-], `contact_ratio_steps` [-];
    `scheduler` (Dask scheduler address such as "tcp://host:8786", or `None` for local).
    """

    speed_rpm_start: float = 20000.0
    speed_rpm_stop: float = 32000.0
    speed_steps: int = 49
    contact_ratio_start: float = 1.35
    contact_ratio_stop: float = 1.65
    contact_ratio_steps: int = 7
    scheduler: str | None = None


@dataclass(frozen=True)
class StudyParameter:
    """One varied config key of a study.

    **Fields:** `key` as written in ``[study.parameters]``, canonical: ``"section.key"`` or, for
    one entry of a list-valued key, ``"section.key[i]"`` (0-based); `section`, `name`, `index`
    (the entry, or `None`); `values` (kind "grid": the values in order, TOML-shaped, checked per
    sample by the normal loader); `distribution` (kind "monte_carlo": one of
    :data:`STUDY_DISTRIBUTIONS`) and its `arguments`.
    """

    key: str
    section: str
    name: str
    index: int | None = None
    values: tuple = ()
    distribution: str | None = None
    arguments: tuple = ()


@dataclass(frozen=True, kw_only=True)
class StudyConfig:
    """A study: many frequency-response curves, one per sample of the varied config keys.

    **Fields:** `kind` ("grid": every combination of the `values`, the last key fastest;
    "monte_carlo": `samples` independent draws, reproducible from `seed`); `parameters` (tuple of
    :class:`StudyParameter`, in the order of the table; empty: the config defines no study);
    `samples`, `seed` (monte_carlo only); `scheduler` (Dask scheduler address, or `None` for local processes).
    """

    kind: str = "grid"
    parameters: tuple[StudyParameter, ...] = ()
    samples: int | None = None
    seed: int = 0
    scheduler: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The ``[study]`` table as in the TOML file (canonical dotted keys)."""
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "monte_carlo":
            out |= {"samples": self.samples, "seed": self.seed}
        if self.scheduler is not None:
            out["scheduler"] = self.scheduler
        out["parameters"] = {p.key: list(p.values) if p.distribution is None else {p.distribution: list(p.arguments)}
                             for p in self.parameters}
        return out


@dataclass(frozen=True, kw_only=True)
class RunConfig:
    """A whole validated run configuration (all SI)."""

    gear: GearConfig
    mesh: MeshConfig
    load: LoadConfig
    profile: ProfileConfig = field(default_factory=ProfileConfig)
    friction: FrictionConfig = field(default_factory=FrictionConfig)
    boundary: BoundaryConfig = field(default_factory=BoundaryConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    simulate: SimulateConfig = field(default_factory=SimulateConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    map: MapConfig = field(default_factory=MapConfig)
    study: StudyConfig = field(default_factory=StudyConfig)
    bearings: BearingsConfig | None = None
    shafts: ShaftsConfig | None = None

    def __post_init__(self):
        model = self.mesh.stiffness_model
        for end in ("pinion", "gear"):
            bore = getattr(self.gear, f"bore_diameter_{end}_m")
            if bore is not None and model != "potential_energy":
                raise _inapplicable(f"gear.bore_diameter_{end}_mm", bore * 1e3, model)
            if bore is None and model == "potential_energy":
                raise ConfigError(f"gear.bore_diameter_{end}_mm", _MISSING,
                                  "required with mesh.stiffness_model = 'potential_energy' (the blank is clamped "
                                  "at its bore)")
        if model == "rectangular" and self.profile.relieved:
            key = self.profile.relieved[0]
            raise ConfigError(f"profile.{key}", getattr(self.profile, key.removesuffix("_um") + "_m") * 1e6,
                              "0 with mesh.stiffness_model = 'rectangular' (a mesh-level k(t); relief needs a "
                              "per-pair model: 'pair_table', 'iso6336' or 'potential_energy')")

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """The configuration in the TOML keys and units (for provenance in output JSON).

        Optional keys that are unset are left out, so `parse_config(cfg.to_dict())` gives
        back an equal configuration (up to unit-conversion rounding).
        """
        g, m, fr, so = self.gear, self.mesh, self.friction, self.solver
        gear = {
            "teeth_pinion": g.teeth_pinion,
            "teeth_gear": g.teeth_gear,
            "module_mm": g.module_m * 1e3,
            "pressure_angle_deg": math.degrees(g.pressure_angle_rad),
        }
        if g.contact_ratio is not None:
            gear["contact_ratio"] = g.contact_ratio
        else:
            gear["addendum_coefficient"] = g.addendum_coefficient
        gear |= {
            "face_width_mm": g.face_width_m * 1e3,
            "inertia_pinion_kgm2": g.inertia_pinion_kgm2,
            "inertia_gear_kgm2": g.inertia_gear_kgm2,
            "profile_shift_pinion": g.profile_shift_pinion,
            "profile_shift_gear": g.profile_shift_gear,
            "tip_shortening": g.tip_shortening,
        }
        for key, value in (("center_distance_mm", g.working_center_distance_m),
                           ("bore_diameter_pinion_mm", g.bore_diameter_pinion_m),
                           ("bore_diameter_gear_mm", g.bore_diameter_gear_m)):
            if value is not None:
                gear[key] = value * 1e3
        mesh: dict[str, Any] = {"stiffness_model": m.stiffness_model}
        material = {
            "k_max_MN_per_m": None if m.k_max_N_per_m is None else m.k_max_N_per_m * 1e-6,
            "k_mean_MN_per_m": None if m.k_mean_N_per_m is None else m.k_mean_N_per_m * 1e-6,
            "k_min_MN_per_m": None if m.k_min_N_per_m is None else m.k_min_N_per_m * 1e-6,
            "pair_stiffness_file": None if m.pair_stiffness_file is None else str(m.pair_stiffness_file),
            "youngs_modulus_GPa": m.youngs_modulus_Pa * 1e-9,
            "poisson_ratio": m.poisson_ratio,
            "rack_dedendum_coefficient": m.rack_dedendum_coefficient,
            "rack_tip_radius_coefficient": m.rack_tip_radius_coefficient,
            "blank_factor": m.blank_factor,
        }
        mesh |= {k: material[k] for k in MODEL_KEYS[m.stiffness_model] if material[k] is not None}
        mesh |= {
            "damping_ratio": m.damping_ratio,
            "damping_model": m.damping_model,
            "backlash_um": m.backlash_m * 1e6,
            "ste_amplitude_um": [a * 1e6 for a in m.ste_amplitude_m],
            "ste_phase_deg": [math.degrees(p) for p in m.ste_phase_rad],
        }
        sim = self.simulate
        out = {
            "gear": gear,
            "mesh": mesh,
            "load": {"torque_pinion_Nm": self.load.torque_pinion_Nm},
            "profile": self.profile.to_keys(),
            "friction": dataclasses.asdict(fr),
            "boundary": dataclasses.asdict(self.boundary),
            "solver": {
                "harmonics": "auto" if so.harmonics is None else so.harmonics,
                "subharmonic": so.subharmonic,
                "time_samples": so.time_samples,
                "tolerance": so.tolerance,
                "max_iterations": so.max_iterations,
            },
            "simulate": {
                "cycles": sim.cycles,
                "rtol": sim.rtol,
                "atol_um": sim.atol_m * 1e6,
                "steady_tolerance": sim.steady_tolerance,
            },
            "sweep": dataclasses.asdict(self.sweep),
            "map": dataclasses.asdict(self.map),
        }
        for section in ("sweep", "map"):
            out[section] = {k: v for k, v in out[section].items() if v is not None}
        if self.study.parameters:
            out["study"] = self.study.to_dict()
        if self.bearings is not None:
            out["bearings"] = {(k[:-len("_N_per_m")] + "_MN_per_m" if k.endswith("_N_per_m") else k):
                               (v * 1e-6 if k.endswith("_N_per_m") else v)
                               for k, v in dataclasses.asdict(self.bearings).items() if v is not None}
        if self.shafts is not None:
            out["shafts"] = dataclasses.asdict(self.shafts)
        return out


# ----------------------------------------------------------------------------- value checks


class _Missing:
    def __repr__(self) -> str:
        return "<missing>"


_MISSING = _Missing()  # "absent": the dataclass default applies
_NEEDED = object()  # default for required keys


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _as_float(key: str, value: object, allowed: str) -> float:
    """A finite float from a TOML int or float (never a bool), else ConfigError."""
    if not _is_number(value):
        raise ConfigError(key, value, allowed)
    try:
        number = float(value)
    except OverflowError:
        raise ConfigError(key, value, allowed) from None
    if not math.isfinite(number):
        raise ConfigError(key, value, allowed)
    return number


def _real(key, value, *, lo=None, hi=None, lo_open=True, hi_open=True, what="a number"):
    """Finite number with optional bounds; the message states the allowed range."""
    parts = []
    if lo is not None:
        parts.append(f"{'>' if lo_open else '>='} {lo:g}")
    if hi is not None:
        parts.append(f"{'<' if hi_open else '<='} {hi:g}")
    allowed = f"{what} ({', '.join([*parts, 'finite'])})"
    number = _as_float(key, value, allowed)
    if lo is not None and (number < lo or (lo_open and number == lo)):
        raise ConfigError(key, value, allowed)
    if hi is not None and (number > hi or (hi_open and number == hi)):
        raise ConfigError(key, value, allowed)
    return number


def _integer(key, value, lo, hi, what="an integer"):
    allowed = f"{what} in [{lo}, {hi}]"
    if not isinstance(value, int) or isinstance(value, bool) or not lo <= value <= hi:
        raise ConfigError(key, value, allowed)
    return value


def _choice(key, value, choices, *, fold=str.lower):
    allowed = "one of " + ", ".join(repr(c) for c in choices)
    if isinstance(value, str):
        for choice in choices:
            if fold(value.strip()) == fold(choice):
                return choice
    raise ConfigError(key, value, allowed)


def _inapplicable(key: str, value: object, model: str) -> ConfigError:
    """A key given for a stiffness model that does not use it."""
    return ConfigError(key, value, f"not used by mesh.stiffness_model = {model!r} (remove it)")


def _si(key, value, number, scale):
    """`number * scale`, rejecting results that overflow to inf or underflow to 0."""
    result = number * scale
    if not math.isfinite(result) or (number != 0.0 and result == 0.0):
        raise ConfigError(key, value, "a number of a physically sensible size")
    return result


_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _key_text(key: object) -> str:
    """A TOML key as written in a message: bare if possible, else quoted (never multi-line)."""
    key = str(key)
    return key if _BARE_KEY.fullmatch(key) else json.dumps(key)


class _Section:
    """One TOML table: typed access by key plus an unknown-key check."""

    def __init__(self, name: str, table: object, allowed: Sequence[str]):
        if not isinstance(table, Mapping):
            raise ConfigError(name, table, "a TOML table [" + name + "]")
        unknown = [k for k in table if k not in allowed]
        if unknown:
            raise ConfigError(
                f"{name}.{_key_text(unknown[0])}",
                table[unknown[0]],
                f"not a known key of [{name}]; allowed keys: " + ", ".join(allowed),
            )
        self.name = name
        self.table = table

    def key(self, key: str) -> str:
        return f"{self.name}.{key}"

    def has(self, key: str) -> bool:
        return key in self.table

    def raw(self, key: str) -> object:
        return self.table.get(key, _MISSING)

    def get(self, key: str, check: Callable[[str, object], Any], default: Any = _NEEDED):
        """Checked value of `key`; `default` if absent (ConfigError if absent and required)."""
        if key not in self.table:
            if default is _NEEDED:
                try:  # every check rejects _MISSING; reuse its "allowed" text
                    check(self.key(key), _MISSING)
                except ConfigError as exc:
                    allowed = f"required: {exc.allowed}"
                    raise ConfigError(self.key(key), _MISSING, allowed) from None
                raise ConfigError(self.key(key), _MISSING, "required")  # pragma: no cover
            return default
        return check(self.key(key), self.table[key])

    def exclusive(self, first: str, second: str, required: bool) -> str | None:
        """Which of two mutually exclusive keys is present (ConfigError if both)."""
        if first in self.table and second in self.table:
            raise ConfigError(
                self.key(second),
                self.table[second],
                f"give {self.key(first)} or {self.key(second)}, not both",
            )
        if first in self.table:
            return first
        if second in self.table:
            return second
        if required:
            raise ConfigError(
                self.key(first), _MISSING, f"required (or give {self.key(second)} instead)"
            )
        return None


# ----------------------------------------------------------------------------- sections


def _num(lo=None, hi=None, *, lo_open=True, hi_open=True, what="a number", scale=None):
    """A checker for a finite number in a range, optionally scaled to SI by `scale`."""

    def check(key: str, value: object) -> float:
        number = _real(key, value, lo=lo, hi=hi, lo_open=lo_open, hi_open=hi_open, what=what)
        return number if scale is None else _si(key, value, number, scale)

    return check


def _int(lo: int, hi: int = MAX_COUNT):
    return lambda key, value: _integer(key, value, lo, hi)


def _one_of(choices: Sequence[str], fold=str.lower):
    return lambda key, value: _choice(key, value, choices, fold=fold)


def _degrees(lo=None, hi=None, what="an angle in degrees"):
    check = _num(lo, hi, what=what)
    return lambda key, value: math.radians(check(key, value))


def _list(item: Callable[[str, object], float]):
    def check(key: str, value: object) -> tuple[float, ...]:
        if not isinstance(value, list):
            raise ConfigError(key, value, "a list of numbers, e.g. [1.0, 0.5]")
        return tuple(item(f"{key}[{i}]", v) for i, v in enumerate(value))

    return check


def _harmonics(key: str, value: object) -> int | None:
    if isinstance(value, str) and value.strip().lower() == "auto":
        return None
    allowed = f'an integer in [1, {MAX_HARMONICS}] or "auto"'
    if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= MAX_HARMONICS:
        raise ConfigError(key, value, allowed)
    return value


def _bool_or_auto(key: str, value: object) -> bool | None:
    if isinstance(value, bool):
        return value
    if isinstance(value, str) and value.strip().lower() == "auto":
        return None
    raise ConfigError(key, value, 'true, false or "auto"')


def _boolean(key: str, value: object) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(key, value, "true or false")
    return value


def _file(key: str, value: object) -> Path:
    if not isinstance(value, str) or not value.strip() or "\x00" in value:
        raise ConfigError(key, value, "a file name (a path relative to the config file's directory, or absolute)")
    return Path(value.strip())


def _address(key: str, value: object) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(key, value, 'a Dask scheduler address such as "tcp://host:8786"')
    return value.strip()


_POSITIVE = _num(0.0, what="a positive number")
_SPEED = _num(0.0, what="a positive speed in rpm")
_RATIO = _num(0.0, 1.0, lo_open=False)  # damping ratios: 0 <= zeta < 1
_CONTACT = _num(1.0, 2.0, what="a contact ratio")
_SHIFT = _num(-1.0, 1.5, lo_open=False, hi_open=False, what="a profile shift coefficient")
_STIFFNESS = _num(0.0, what="a positive stiffness in MN/m", scale=1e6)
_INERTIA = _num(0.0, what="a positive inertia in kg m^2")
_MM = "a positive length in mm"


class _Key(NamedTuple):
    field: str  # dataclass field it fills
    check: Callable[[str, object], Any]  # (dotted key, raw value) -> SI value, or ConfigError
    required: bool = False


def _section(name: str, cls: type, spec: Mapping[str, _Key], post=None):
    """Parser for one TOML table: each key is checked in order; absent optional keys keep the
    dataclass defaults. `post(section, kwargs)` handles exclusive keys and derived fields."""

    def parse(table: object):
        s = _Section(name, table, tuple(spec))
        kwargs = {}
        for key, (field_name, check, required) in spec.items():
            if s.has(key) or required:
                kwargs[field_name] = s.get(key, check)
        return cls(**(post(s, kwargs) if post else kwargs))

    parse.keys = tuple(spec)  # the section's keys (a study may vary any of them)
    return parse


def _gear_post(s: _Section, kw: dict[str, Any]) -> dict[str, Any]:
    shifted = kw.get("profile_shift_pinion", 0.0) != 0.0 or kw.get("profile_shift_gear", 0.0) != 0.0
    if s.has("module_mm") and s.has("center_distance_mm"):
        if not shifted:
            raise ConfigError(s.key("center_distance_mm"), s.raw("center_distance_mm"),
                              "give gear.module_mm or gear.center_distance_mm, not both (both only for a profile-"
                              "shifted pair, where center_distance_mm is the working centre distance)")
        kw["working_center_distance_m"] = kw.pop("center_distance_m")  # a_w of the shifted pair
    elif s.exclusive("module_mm", "center_distance_mm", required=True) == "center_distance_mm":
        key, value = s.key("center_distance_mm"), s.raw("center_distance_mm")
        if shifted:
            raise ConfigError(key, value, "with profile shift also give gear.module_mm (center_distance_mm is then "
                                          "the working centre distance)")
        teeth = kw["teeth_pinion"] + kw["teeth_gear"]
        kw["module_m"] = _si(key, value, kw.pop("center_distance_m"), 2.0 / teeth)
    s.exclusive("contact_ratio", "addendum_coefficient", required=False)
    return kw


def _mesh_post(s: _Section, kw: dict[str, Any]) -> dict[str, Any]:
    model = kw.get("stiffness_model", "rectangular")
    for key in _MESH:
        if s.has(key) and any(key in keys for keys in MODEL_KEYS.values()) and key not in MODEL_KEYS[model]:
            raise _inapplicable(s.key(key), s.raw(key), model)
    kw.setdefault("ste_amplitude_m", ())
    kw.setdefault("ste_phase_rad", (0.0,) * len(kw["ste_amplitude_m"]))
    if len(kw["ste_phase_rad"]) != len(kw["ste_amplitude_m"]):
        n = len(kw["ste_amplitude_m"])
        raise ConfigError(s.key("ste_phase_deg"), s.raw("ste_phase_deg"),
                          f"a list of the same length as mesh.ste_amplitude_um ({n})")
    if model == "pair_table":
        s.get("pair_stiffness_file", _file)  # the "required" message when absent
    if model != "rectangular":
        kw.setdefault("damping_model", "proportional")  # the dynamic commands refuse another one
        return kw
    s.get("k_max_MN_per_m", _STIFFNESS)  # the "required" message when absent
    other = s.exclusive("k_mean_MN_per_m", "k_min_MN_per_m", required=True)
    field_name = _MESH[other].field
    if kw[field_name] > kw["k_max_N_per_m"]:
        limit = kw["k_max_N_per_m"] * 1e-6
        allowed = f"a stiffness <= mesh.k_max_MN_per_m = {limit:g}"
        raise ConfigError(s.key(other), s.raw(other), allowed)
    return kw


_GEAR = {
    "teeth_pinion": _Key("teeth_pinion", _int(5, MAX_TEETH), True),
    "teeth_gear": _Key("teeth_gear", _int(5, MAX_TEETH), True),
    "module_mm": _Key("module_m", _num(0.0, what=_MM, scale=1e-3)),
    "center_distance_mm": _Key("center_distance_m", _num(0.0, what=_MM, scale=1e-3)),
    "pressure_angle_deg": _Key("pressure_angle_rad", _degrees(5.0, 40.0)),
    "contact_ratio": _Key("contact_ratio", _CONTACT),
    "addendum_coefficient": _Key("addendum_coefficient", _num(0.0, 2.0, hi_open=False)),
    "face_width_mm": _Key("face_width_m", _num(0.0, what=_MM, scale=1e-3)),
    "inertia_pinion_kgm2": _Key("inertia_pinion_kgm2", _INERTIA, True),
    "inertia_gear_kgm2": _Key("inertia_gear_kgm2", _INERTIA, True),
    "profile_shift_pinion": _Key("profile_shift_pinion", _SHIFT),
    "profile_shift_gear": _Key("profile_shift_gear", _SHIFT),
    "tip_shortening": _Key("tip_shortening", _boolean),
    "bore_diameter_pinion_mm": _Key("bore_diameter_pinion_m", _num(0.0, what=_MM, scale=1e-3)),
    "bore_diameter_gear_mm": _Key("bore_diameter_gear_m", _num(0.0, what=_MM, scale=1e-3)),
}
_MESH = {
    "stiffness_model": _Key("stiffness_model", _one_of(STIFFNESS_MODELS)),
    "k_max_MN_per_m": _Key("k_max_N_per_m", _STIFFNESS),  # required with "rectangular" (_mesh_post)
    "k_mean_MN_per_m": _Key("k_mean_N_per_m", _STIFFNESS),
    "k_min_MN_per_m": _Key("k_min_N_per_m", _STIFFNESS),
    "pair_stiffness_file": _Key("pair_stiffness_file", _file),
    "youngs_modulus_GPa": _Key("youngs_modulus_Pa", _num(0.0, 1000.0, what="a Young's modulus in GPa", scale=1e9)),
    "poisson_ratio": _Key("poisson_ratio", _num(0.0, 0.5, what="a Poisson ratio")),
    "rack_dedendum_coefficient": _Key("rack_dedendum_coefficient",
                                      _num(1.0, 1.6, lo_open=False, hi_open=False, what="h_fP/m of the basic rack")),
    "rack_tip_radius_coefficient": _Key("rack_tip_radius_coefficient",
                                        _num(0.0, 0.5, lo_open=False, hi_open=False, what="rho_fP/m of the basic rack")),
    "blank_factor": _Key("blank_factor", _num(0.0, 1.0, hi_open=False, what="the gear-blank factor C_R")),
    "damping_ratio": _Key("damping_ratio", _RATIO),
    "damping_model": _Key("damping_model", _one_of(DAMPING_MODELS)),
    "backlash_um": _Key("backlash_m", _num(0.0, lo_open=False, scale=1e-6)),
    "ste_amplitude_um": _Key("ste_amplitude_m", _list(_num(0.0, lo_open=False, scale=1e-6))),
    "ste_phase_deg": _Key("ste_phase_rad", _list(_degrees())),
}
_gear = _section("gear", GearConfig, _GEAR, _gear_post)
_mesh = _section("mesh", MeshConfig, _MESH, _mesh_post)
_RELIEF_UM = _num(0.0, lo_open=False, what="a relief amount in um (>= 0)", scale=1e-6)
_RELIEF_MM = _num(0.0, lo_open=False, what="a relief length in mm (>= 0)", scale=1e-3)
_profile = _section("profile", ProfileConfig, {
    **{f"{name}{unit}": _Key(f"{name}{field_unit}", check) for name in _RELIEFS
       for unit, field_unit, check in (("_um", "_m", _RELIEF_UM), ("_length_mm", "_length_m", _RELIEF_MM))},
    "shape": _Key("shape", _one_of(PROFILE_SHAPES)),
})
_load = _section("load", LoadConfig, {
    "torque_pinion_Nm": _Key("torque_pinion_Nm", _num(0.0, what="a positive torque in N m"), True),
})
_friction = _section("friction", FrictionConfig, {
    "law": _Key("law", _one_of(FRICTION_LAWS)),
    "mu0": _Key("mu0", _num(0.0, 1.0, lo_open=False, hi_open=False)),
    "v0_m_per_s": _Key("v0_m_per_s", _POSITIVE),
    "formulation": _Key("formulation", _one_of(FRICTION_FORMULATIONS, fold=str.upper)),
    "model": _Key("model", _one_of(FRICTION_MODELS, fold=str.upper)),
    "viscosity_Pa_s": _Key("viscosity_Pa_s", _POSITIVE),
    "roughness_um": _Key("roughness_um", _num(0.0, lo_open=False)),
    "regularization_m_per_s": _Key("regularization_m_per_s", _POSITIVE),
    "lti_friction": _Key("lti_friction", _one_of(LTI_FRICTION)),
})
_boundary = _section("boundary", BoundaryConfig, {
    "output": _Key("output", _one_of(BOUNDARY_OUTPUTS)),
    "stiffness_ratio": _Key("stiffness_ratio", _num(1.0)),
    "damping_ratio": _Key("damping_ratio", _RATIO),
})
_solver = _section("solver", SolverConfig, {
    "harmonics": _Key("harmonics", _harmonics),
    "subharmonic": _Key("subharmonic", _int(1, 2)),
    "time_samples": _Key("time_samples", _int(16, MAX_TIME_SAMPLES)),
    "tolerance": _Key("tolerance", _num(0.0, 1e-2)),
    "max_iterations": _Key("max_iterations", _int(1)),
})  # time_samples >= 2 H nu + 2 is checked by SolverConfig itself
_simulate = _section("simulate", SimulateConfig, {
    "cycles": _Key("cycles", _int(2)),
    "rtol": _Key("rtol", _num(0.0, 1e-3)),
    "atol_um": _Key("atol_m", _num(0.0, what="a positive tolerance in um", scale=1e-6)),
    "steady_tolerance": _Key("steady_tolerance", _num(0.0, 1.0)),
})
_sweep = _section("sweep", SweepConfig, {
    "speed_rpm_start": _Key("speed_rpm_start", _SPEED),
    "speed_rpm_stop": _Key("speed_rpm_stop", _SPEED),
    "max_points": _Key("max_points", _int(2)),
    "step_rpm": _Key("step_rpm", _num(0.0, what="a positive step in rpm")),
    "period_doubling": _Key("period_doubling", _bool_or_auto),
    "orders": _Key("orders", _int(1, MAX_HARMONICS)),
})  # start != stop is checked by SweepConfig itself; orders <= H / nu by the frc command
_BEARING_STIFFNESS = _num(0.0, what="a positive stiffness in MN/m", scale=1e6)
_bearings = _section("bearings", BearingsConfig, {
    **{f"{end}{direction}_stiffness_MN_per_m": _Key(f"{end}{direction}_stiffness_N_per_m", _BEARING_STIFFNESS)
       for end in ("pinion", "gear") for direction in ("", "_loa", "_oloa")},
    "damping_ratio": _Key("damping_ratio", _RATIO),
    "mass_pinion_kg": _Key("mass_pinion_kg", _num(0.0, what="a positive mass in kg")),
    "mass_gear_kg": _Key("mass_gear_kg", _num(0.0, what="a positive mass in kg")),
})
_shafts = _section("shafts", ShaftsConfig, {
    "drive_inertia_kgm2": _Key("drive_inertia_kgm2", _num(0.0, what="a positive inertia in kg m^2"), True),
    "load_inertia_kgm2": _Key("load_inertia_kgm2", _num(0.0, what="a positive inertia in kg m^2"), True),
    "drive_stiffness_Nm_per_rad": _Key("drive_stiffness_Nm_per_rad",
                                       _num(0.0, what="a positive torsional stiffness in N m/rad"), True),
    "load_stiffness_Nm_per_rad": _Key("load_stiffness_Nm_per_rad",
                                      _num(0.0, what="a positive torsional stiffness in N m/rad"), True),
    "damping_ratio": _Key("damping_ratio", _RATIO),
})
_map = _section("map", MapConfig, {
    "speed_rpm_start": _Key("speed_rpm_start", _SPEED),
    "speed_rpm_stop": _Key("speed_rpm_stop", _SPEED),
    "speed_steps": _Key("speed_steps", _int(1)),
    "contact_ratio_start": _Key("contact_ratio_start", _CONTACT),
    "contact_ratio_stop": _Key("contact_ratio_stop", _CONTACT),
    "contact_ratio_steps": _Key("contact_ratio_steps", _int(1)),
    "scheduler": _Key("scheduler", _address),
})


# ----------------------------------------------------------------------------- [study]

_STUDY_KEY = re.compile(r"([A-Za-z0-9_-]+)\.([A-Za-z0-9_-]+)(?:\[([0-9]+)\])?")
_DISTRIBUTION_TEXT = ("{ normal = [mean, std] }, { uniform = [low, high] }, { lognormal = [mu, sigma] } "
                      "(of the logarithm) or { choice = [value, ...] }")


def _is_distribution(value: object) -> bool:
    return isinstance(value, Mapping) and len(value) == 1 and next(iter(value)) in STUDY_DISTRIBUTIONS


def _flat_parameters(table: Mapping, prefix: str = "") -> list[tuple[str, object]]:
    """``[study.parameters]`` as ``(dotted key, value)`` pairs: quoted keys (``"mesh.damping_ratio"``)
    and TOML's nested spelling (``mesh.damping_ratio = ...``, a table ``mesh``) read alike."""
    pairs = []
    for key, value in table.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping) and not prefix and "." not in dotted and not _is_distribution(value):
            pairs += _flat_parameters(value, dotted)  # a section's table
        else:
            pairs.append((dotted, value))
    return pairs


def _study_key(where: str, key: str, value: object) -> tuple[str, str, int | None]:
    """``(section, name, index)`` of a varied key, checked against the known sections and keys."""
    match = _STUDY_KEY.fullmatch(key)
    if match is None:
        raise ConfigError(where, value, 'a dotted config key "section.key", or "section.key[i]" for entry i of a list')
    section, name, index = match.group(1), match.group(2), match.group(3)
    if section not in _SECTIONS or section == "study":
        allowed = ", ".join(s for s in _SECTIONS if s != "study")
        raise ConfigError(where, value, f"a key of a config section ({allowed})")
    keys = getattr(_SECTIONS[section], "keys", None)
    if keys is not None and name not in keys:
        raise ConfigError(where, value, f"a key of [{section}]: " + ", ".join(keys))
    return section, name, None if index is None else int(index)


def _distribution(where: str, value: Mapping) -> tuple[str, tuple]:
    """``(name, arguments)`` of a checked distribution table."""
    name, args = next(iter(value.items()))
    if name == "choice":
        if not isinstance(args, list) or not args:
            raise ConfigError(where, value, "{ choice = [value, ...] } with at least one value")
        return name, tuple(args)
    text = {"normal": "[mean, std] with std >= 0", "uniform": "[low, high] with low <= high",
            "lognormal": "[mu, sigma] (mean and std of ln x) with sigma >= 0"}[name]
    if not isinstance(args, list) or len(args) != 2 or not all(_is_number(a) and math.isfinite(a) for a in args):
        raise ConfigError(where, value, f"{{ {name} = {text} }}, finite numbers")
    a, b = (float(x) for x in args)
    if (b < 0.0) if name != "uniform" else (b < a):
        raise ConfigError(where, value, f"{{ {name} = {text} }}")
    return name, (a, b)


def _study_parameter(kind: str, where: str, key: str, value: object) -> StudyParameter:
    section, name, index = _study_key(where, key, value)
    canonical = f"{section}.{name}" + ("" if index is None else f"[{index}]")
    if kind == "grid":
        if not isinstance(value, list) or not value:
            allowed = ('a non-empty list of values (kind = "grid"); distributions need kind = "monte_carlo"'
                       if isinstance(value, Mapping) else 'a non-empty list of values (kind = "grid")')
            raise ConfigError(where, value, allowed)
        return StudyParameter(canonical, section, name, index, values=tuple(value))
    if not _is_distribution(value):
        raise ConfigError(where, value, f'a distribution (kind = "monte_carlo"): {_DISTRIBUTION_TEXT}')
    dist, args = _distribution(where, value)
    return StudyParameter(canonical, section, name, index, distribution=dist, arguments=args)


def _study(table: object) -> StudyConfig:
    """``[study]``: kind, samples and seed (monte_carlo), scheduler, and ``[study.parameters]``."""
    s = _Section("study", table, ("kind", "samples", "seed", "scheduler", "parameters"))
    kind = s.get("kind", _one_of(STUDY_KINDS), "grid")
    for key in ("samples", "seed"):
        if kind == "grid" and s.has(key):
            raise ConfigError(s.key(key), s.raw(key), 'only with study.kind = "monte_carlo"')
    samples = s.get("samples", _int(1, MAX_STUDY_SAMPLES)) if kind == "monte_carlo" else None
    seed = s.get("seed", _int(0, 2**63 - 1), 0)
    scheduler = s.get("scheduler", _address, None)
    raw = s.get("parameters", lambda key, value: value)
    if not isinstance(raw, Mapping) or not raw:
        raise ConfigError(s.key("parameters"), raw, 'a table [study.parameters] of "section.key" = values')
    parameters, targets = [], {}
    for key, value in _flat_parameters(raw):
        where = f"study.parameters.{_key_text(key)}"
        parameter = _study_parameter(kind, where, key, value)
        whole, entry = (parameter.section, parameter.name), (parameter.section, parameter.name, parameter.index)
        clash = [k for k, t in targets.items() if t == entry or t[:2] == whole and None in (t[2], parameter.index)]
        if clash:
            raise ConfigError(where, value, f"a key not varied already (study.parameters.{_key_text(clash[0])})")
        targets[parameter.key] = entry
        parameters.append(parameter)
    if kind == "grid" and math.prod(len(p.values) for p in parameters) > MAX_STUDY_SAMPLES:
        raise ConfigError(s.key("parameters"), raw, f"a grid of at most {MAX_STUDY_SAMPLES} samples")
    return StudyConfig(kind=kind, parameters=tuple(parameters), samples=samples, seed=seed, scheduler=scheduler)

_SECTIONS: dict[str, Callable[[object], Any]] = {
    "gear": _gear,
    "mesh": _mesh,
    "load": _load,
    "profile": _profile,
    "friction": _friction,
    "boundary": _boundary,
    "solver": _solver,
    "simulate": _simulate,
    "sweep": _sweep,
    "map": _map,
    "study": _study,
    "bearings": _bearings,
    "shafts": _shafts,
}
_REQUIRED = ("gear", "mesh", "load")


# ----------------------------------------------------------------------------- public API


def _parse_value(text: str) -> object:
    """An override value: a TOML value if it parses as one, else the bare string."""
    try:
        parsed = tomllib.loads(f"v = {text}")
    except tomllib.TOMLDecodeError:
        return text.strip()
    if set(parsed) != {"v"}:
        return text.strip()
    return parsed["v"]


def apply_overrides(data: Mapping[str, Any], overrides: Sequence[str]) -> dict[str, Any]:
    """A copy of `data` with each `section.key=value` override applied.

    The value is read as a TOML value when it is one (`harmonics=32` -> int,
    `ste_amplitude_um=[1.0, 0.5]` -> list, `damping_ratio=nan` -> float nan), otherwise taken
    as a bare string (`law=arctan` -> "arctan"). Values are checked later by
    :func:`parse_config`.

    **Raises:** `ConfigError("--set", text, ...)` for a malformed override.
    """
    result = copy.deepcopy(dict(data))
    if isinstance(overrides, str):
        overrides = [overrides]
    for text in overrides:
        if not isinstance(text, str) or "=" not in text:
            raise ConfigError("--set", text, "section.key=value")
        lhs, value = text.split("=", 1)
        section, dot, key = lhs.strip().partition(".")
        section, key = section.strip(), key.strip()
        if not (_BARE_KEY.fullmatch(section) and _BARE_KEY.fullmatch(key)):
            raise ConfigError("--set", text, "section.key=value")
        table = result.setdefault(section, {})
        if not isinstance(table, dict):
            raise ConfigError(section, table, f"a TOML table [{section}]")
        table[key] = _parse_value(value)
    return result


def parse_config(data: Mapping[str, Any], overrides: Sequence[str] = (), base_dir: str | Path | None = None
                 ) -> RunConfig:
    """Validate a TOML-shaped dict (after applying `overrides`) into a :class:`RunConfig`.

    Relative file names (`mesh.pair_stiffness_file`) are taken from `base_dir` (the config
    file's directory; default the current directory) and stored absolute.

    **Raises:** :class:`~hbgear.errors.ConfigError` naming the first bad key.
    """
    if not isinstance(data, Mapping):
        raise ConfigError("config", data, "a TOML document with tables " + ", ".join(_SECTIONS))
    data = apply_overrides(data, overrides)
    for name in data:
        if name not in _SECTIONS:
            raise ConfigError(
                _key_text(name),
                data[name],
                "not a known section; allowed sections: "
                + ", ".join(f"[{s}]" for s in _SECTIONS),
            )
    for name in _REQUIRED:
        if name not in data:
            raise ConfigError(name, _MISSING, f"a required section [{name}]")
    sections = {name: _SECTIONS[name](data[name]) for name in data}
    mesh = sections["mesh"]
    if mesh.pair_stiffness_file is not None:
        path = Path(base_dir if base_dir is not None else Path.cwd(), mesh.pair_stiffness_file).absolute()
        sections["mesh"] = dataclasses.replace(mesh, pair_stiffness_file=path)
    return RunConfig(**sections)


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a TOML file, apply `section.key=value` overrides, validate.

    **Raises:** :class:`~hbgear.errors.ConfigError` -- key `"config"` when the file is
    missing, unreadable or not valid TOML; otherwise the dotted key of the bad value.
    """
    return parse_config(read_toml(path), overrides, base_dir=Path(path).parent)


def read_toml(path: str | Path) -> dict[str, Any]:
    """The TOML document at `path` as a dict, unchecked (:func:`parse_config` checks it).

    **Raises:** ``ConfigError("config", path, ...)`` when the file is missing, unreadable or
    not valid TOML.
    """
    try:
        text = Path(path).read_bytes().decode("utf-8")
        return tomllib.loads(text)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ConfigError("config", str(path), f"a readable TOML file ({reason})") from None
    except UnicodeDecodeError:
        raise ConfigError("config", str(path), "a readable TOML file (not UTF-8 text)") from None
    except tomllib.TOMLDecodeError as exc:
        reason = " ".join(str(exc).split())
        raise ConfigError("config", str(path), f"a readable TOML file ({reason})") from None
