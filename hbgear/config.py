"""TOML run configuration -> frozen, typed, validated dataclasses in SI units.

The TOML file uses engineering units spelled out in the key names (`module_mm`,
`k_max_MN_per_m`, `backlash_um`, `pressure_angle_deg`, ...); everything stored in the
dataclasses below is SI (m, N/m, rad, kg m^2, N m, s) and the field names say so.

Every value is checked when the file is read: its type (an integer is not a float where an
integer is required; a boolean is never a number), that it is finite, its range, allowed
names, mutually exclusive keys, and unknown sections or keys (the message lists the allowed
ones). Any problem raises :class:`hbgear.errors.ConfigError` with the dotted key, the value
given and what is allowed. Checks that need the gear geometry (e.g. the contact ratio that an
`addendum_coefficient` produces) belong to the physics code.

**Public API:** :func:`load_config`, :func:`parse_config`, :func:`apply_overrides`,
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
    "RunConfig",
    "SimulateConfig",
    "SolverConfig",
    "SweepConfig",
    "apply_overrides",
    "load_config",
    "parse_config",
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


# ----------------------------------------------------------------------------- dataclasses


@dataclass(frozen=True, kw_only=True)
class GearConfig:
    """Spur-gear pair geometry and inertias.

    **Fields:** `teeth_pinion`, `teeth_gear` [-]; `module_m` [m]; `pressure_angle_rad` [rad];
    `contact_ratio` [-] (target profile contact ratio, or `None`) XOR `addendum_coefficient`
    [-] (same on both gears; 1.0 when neither is given); `face_width_m` [m];
    `inertia_pinion_kgm2`, `inertia_gear_kgm2` [kg m^2].
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

    def __post_init__(self):
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

    **Fields:** `k_max_N_per_m` [N/m] (two pairs in contact); `k_mean_N_per_m` XOR
    `k_min_N_per_m` [N/m] (the other follows from the contact ratio); `damping_ratio` [-];
    `damping_model` ("constant" or "proportional" to k(t)); `backlash_m` [m] (total);
    `ste_amplitude_m` [m] and `ste_phase_rad` [rad], one entry per mesh order 1, 2, ...
    """

    k_max_N_per_m: float
    k_mean_N_per_m: float | None = None
    k_min_N_per_m: float | None = None
    damping_ratio: float = 0.01
    damping_model: str = "constant"
    backlash_m: float = 0.0
    ste_amplitude_m: tuple[float, ...] = ()
    ste_phase_rad: tuple[float, ...] = ()

    def __post_init__(self):
        if (self.k_mean_N_per_m is None) == (self.k_min_N_per_m is None):
            raise ConfigError(
                "mesh.k_mean_MN_per_m",
                self.k_mean_N_per_m,
                "give exactly one of mesh.k_mean_MN_per_m and mesh.k_min_MN_per_m",
            )
        if len(self.ste_phase_rad) != len(self.ste_amplitude_m):
            raise ConfigError(
                "mesh.ste_phase_deg",
                list(self.ste_phase_rad),
                "a list of the same length as mesh.ste_amplitude_um "
                f"({len(self.ste_amplitude_m)})",
            )


@dataclass(frozen=True, kw_only=True)
class LoadConfig:
    """Static load. **Fields:** `torque_pinion_Nm` [N m], input torque on the pinion."""

    torque_pinion_Nm: float


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
    ``None`` for "auto" (only where the nu = 2 problem is small; crossings are always located).
    """

    speed_rpm_start: float = 1000.0
    speed_rpm_stop: float = 20000.0
    max_points: int = 4000
    step_rpm: float | None = None
    period_doubling: bool | None = None

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


@dataclass(frozen=True, kw_only=True)
class RunConfig:
    """A whole validated run configuration (all SI)."""

    gear: GearConfig
    mesh: MeshConfig
    load: LoadConfig
    friction: FrictionConfig = field(default_factory=FrictionConfig)
    boundary: BoundaryConfig = field(default_factory=BoundaryConfig)
    solver: SolverConfig = field(default_factory=SolverConfig)
    simulate: SimulateConfig = field(default_factory=SimulateConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    map: MapConfig = field(default_factory=MapConfig)

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
        }
        mesh: dict[str, Any] = {"k_max_MN_per_m": m.k_max_N_per_m * 1e-6}
        if m.k_mean_N_per_m is not None:
            mesh["k_mean_MN_per_m"] = m.k_mean_N_per_m * 1e-6
        else:
            mesh["k_min_MN_per_m"] = m.k_min_N_per_m * 1e-6
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


def _address(key: str, value: object) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ConfigError(key, value, 'a Dask scheduler address such as "tcp://host:8786"')
    return value.strip()


_POSITIVE = _num(0.0, what="a positive number")
_SPEED = _num(0.0, what="a positive speed in rpm")
_RATIO = _num(0.0, 1.0, lo_open=False)  # damping ratios: 0 <= zeta < 1
_CONTACT = _num(1.0, 2.0, what="a contact ratio")
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

    return parse


def _gear_post(s: _Section, kw: dict[str, Any]) -> dict[str, Any]:
    if s.exclusive("module_mm", "center_distance_mm", required=True) == "center_distance_mm":
        key, value = s.key("center_distance_mm"), s.raw("center_distance_mm")
        teeth = kw["teeth_pinion"] + kw["teeth_gear"]
        kw["module_m"] = _si(key, value, kw.pop("center_distance_m"), 2.0 / teeth)
    s.exclusive("contact_ratio", "addendum_coefficient", required=False)
    return kw


def _mesh_post(s: _Section, kw: dict[str, Any]) -> dict[str, Any]:
    other = s.exclusive("k_mean_MN_per_m", "k_min_MN_per_m", required=True)
    field_name = _MESH[other].field
    if kw[field_name] > kw["k_max_N_per_m"]:
        limit = kw["k_max_N_per_m"] * 1e-6
        allowed = f"a stiffness <= mesh.k_max_MN_per_m = {limit:g}"
        raise ConfigError(s.key(other), s.raw(other), allowed)
    kw.setdefault("ste_amplitude_m", ())
    kw.setdefault("ste_phase_rad", (0.0,) * len(kw["ste_amplitude_m"]))
    if len(kw["ste_phase_rad"]) != len(kw["ste_amplitude_m"]):
        n = len(kw["ste_amplitude_m"])
        raise ConfigError(s.key("ste_phase_deg"), s.raw("ste_phase_deg"),
                          f"a list of the same length as mesh.ste_amplitude_um ({n})")
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
}
_MESH = {
    "k_max_MN_per_m": _Key("k_max_N_per_m", _STIFFNESS, True),
    "k_mean_MN_per_m": _Key("k_mean_N_per_m", _STIFFNESS),
    "k_min_MN_per_m": _Key("k_min_N_per_m", _STIFFNESS),
    "damping_ratio": _Key("damping_ratio", _RATIO),
    "damping_model": _Key("damping_model", _one_of(DAMPING_MODELS)),
    "backlash_um": _Key("backlash_m", _num(0.0, lo_open=False, scale=1e-6)),
    "ste_amplitude_um": _Key("ste_amplitude_m", _list(_num(0.0, lo_open=False, scale=1e-6))),
    "ste_phase_deg": _Key("ste_phase_rad", _list(_degrees())),
}
_gear = _section("gear", GearConfig, _GEAR, _gear_post)
_mesh = _section("mesh", MeshConfig, _MESH, _mesh_post)
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
})  # start != stop is checked by SweepConfig itself
_map = _section("map", MapConfig, {
    "speed_rpm_start": _Key("speed_rpm_start", _SPEED),
    "speed_rpm_stop": _Key("speed_rpm_stop", _SPEED),
    "speed_steps": _Key("speed_steps", _int(1)),
    "contact_ratio_start": _Key("contact_ratio_start", _CONTACT),
    "contact_ratio_stop": _Key("contact_ratio_stop", _CONTACT),
    "contact_ratio_steps": _Key("contact_ratio_steps", _int(1)),
    "scheduler": _Key("scheduler", _address),
})

_SECTIONS: dict[str, Callable[[object], Any]] = {
    "gear": _gear,
    "mesh": _mesh,
    "load": _load,
    "friction": _friction,
    "boundary": _boundary,
    "solver": _solver,
    "simulate": _simulate,
    "sweep": _sweep,
    "map": _map,
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


def parse_config(data: Mapping[str, Any], overrides: Sequence[str] = ()) -> RunConfig:
    """Validate a TOML-shaped dict (after applying `overrides`) into a :class:`RunConfig`.

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
    return RunConfig(**{name: _SECTIONS[name](data[name]) for name in data})


def load_config(path: str | Path, overrides: Sequence[str] = ()) -> RunConfig:
    """Read a TOML file, apply `section.key=value` overrides, validate.

    **Raises:** :class:`~hbgear.errors.ConfigError` -- key `"config"` when the file is
    missing, unreadable or not valid TOML; otherwise the dotted key of the bad value.
    """
    try:
        text = Path(path).read_bytes().decode("utf-8")
        data = tomllib.loads(text)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ConfigError("config", str(path), f"a readable TOML file ({reason})") from None
    except UnicodeDecodeError:
        raise ConfigError("config", str(path), "a readable TOML file (not UTF-8 text)") from None
    except tomllib.TOMLDecodeError as exc:
        reason = " ".join(str(exc).split())
        raise ConfigError("config", str(path), f"a readable TOML file ({reason})") from None
    return parse_config(data, overrides)
