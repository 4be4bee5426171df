"""hbgear.config: TOML -> validated SI dataclasses; every bad input is a ConfigError."""

import copy
import dataclasses
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hbgear.config import (
    GearConfig,
    MeshConfig,
    RunConfig,
    SolverConfig,
    apply_overrides,
    load_config,
    parse_config,
)
from hbgear.errors import ConfigError

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"

BASE = {
    "gear": {
        "teeth_pinion": 25,
        "teeth_gear": 31,
        "module_mm": 3.175,
        "pressure_angle_deg": 20.0,
        "contact_ratio": 1.433,
        "face_width_mm": 20.0,
        "inertia_pinion_kgm2": 1.0594e-3,
        "inertia_gear_kgm2": 2.5047e-3,
    },
    "mesh": {"k_max_MN_per_m": 720.0, "k_mean_MN_per_m": 568.0, "damping_ratio": 0.01},
    "load": {"torque_pinion_Nm": 226.0},
    "friction": {"law": "coulomb", "mu0": 0.1, "formulation": "A", "model": "LTV"},
    "boundary": {"output": "spring", "stiffness_ratio": 5e5, "damping_ratio": 0.0},
    "solver": {"harmonics": 32, "subharmonic": 1, "time_samples": 256, "tolerance": 1e-9},
    "simulate": {"cycles": 400},
    "sweep": {"speed_rpm_start": 1000.0, "speed_rpm_stop": 20000.0, "max_points": 4000},
    "map": {"speed_rpm_start": 20000.0, "speed_rpm_stop": 32000.0, "speed_steps": 49},
}


def base():
    return copy.deepcopy(BASE)


def error_of(data, overrides=()):
    with pytest.raises(ConfigError) as info:
        parse_config(data, overrides)
    return info.value


# ----------------------------------------------------------------------------- good configs


@pytest.mark.parametrize("name", ["paper_table1.toml", "low_speed_nltv.toml", "backlash.toml"])
def test_examples_load(name):
    cfg = load_config(EXAMPLES / name)
    assert isinstance(cfg, RunConfig)
    assert cfg.gear.teeth_pinion == 25 and cfg.gear.teeth_gear == 31


def test_paper_example_values_in_si():
    cfg = load_config(EXAMPLES / "paper_table1.toml")
    assert cfg.gear.module_m == pytest.approx(3.175e-3)
    assert cfg.gear.pressure_angle_rad == pytest.approx(math.radians(20.0))
    assert cfg.gear.contact_ratio == 1.433 and cfg.gear.addendum_coefficient is None
    assert cfg.gear.face_width_m == pytest.approx(0.020)
    assert cfg.mesh.k_max_N_per_m == pytest.approx(720e6)
    assert cfg.mesh.k_mean_N_per_m == pytest.approx(568e6) and cfg.mesh.k_min_N_per_m is None
    assert cfg.load.torque_pinion_Nm == 226.0
    assert (cfg.friction.law, cfg.friction.mu0, cfg.friction.formulation) == ("coulomb", 0.1, "A")
    assert cfg.friction.model == "LTV"
    assert cfg.boundary.stiffness_ratio == 5e5 and cfg.boundary.output == "spring"
    assert (cfg.solver.harmonics, cfg.solver.subharmonic, cfg.solver.time_samples) == (32, 1, 1024)
    assert (cfg.sweep.speed_rpm_start, cfg.sweep.speed_rpm_stop) == (1000.0, 20000.0)
    assert cfg.map.speed_steps == 49 and cfg.map.contact_ratio_steps == 7
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.gear.teeth_pinion = 3  # type: ignore[misc]


def test_other_examples():
    nltv = load_config(EXAMPLES / "low_speed_nltv.toml")
    assert nltv.solver.harmonics is None  # "auto"
    assert (nltv.friction.law, nltv.friction.model, nltv.mesh.damping_ratio) == (
        "arctan",
        "NLTV",
        0.05,
    )
    lash = load_config(EXAMPLES / "backlash.toml")
    assert lash.mesh.backlash_m == pytest.approx(40e-6) and lash.friction.mu0 == 0.0


def test_defaults_for_optional_sections():
    data = {k: base()[k] for k in ("gear", "mesh", "load")}
    cfg = parse_config(data)
    assert cfg.friction.law == "coulomb" and cfg.friction.mu0 == 0.1
    assert cfg.solver.harmonics == 24 and cfg.solver.time_samples == 1024
    assert cfg.simulate.atol_m == pytest.approx(1e-15) and cfg.simulate.cycles == 400
    assert cfg.sweep.max_points == 4000 and cfg.sweep.step_rpm is None
    assert cfg.map.speed_rpm_start == 20000.0 and cfg.map.scheduler is None


def test_center_distance_and_addendum_and_k_min():
    data = base()
    del data["gear"]["module_mm"], data["gear"]["contact_ratio"]
    data["gear"]["center_distance_mm"] = 88.9
    del data["mesh"]["k_mean_MN_per_m"]
    data["mesh"]["k_min_MN_per_m"] = 451.9
    cfg = parse_config(data)
    assert cfg.gear.module_m == pytest.approx(2 * 88.9e-3 / 56)
    assert cfg.gear.contact_ratio is None and cfg.gear.addendum_coefficient == 1.0
    assert cfg.mesh.k_min_N_per_m == pytest.approx(451.9e6) and cfg.mesh.k_mean_N_per_m is None


def test_ste_lists_and_phase_default():
    cfg = parse_config(base(), ["mesh.ste_amplitude_um=[1.0, 0.5]"])
    assert cfg.mesh.ste_amplitude_m == pytest.approx((1e-6, 0.5e-6))
    assert cfg.mesh.ste_phase_rad == (0.0, 0.0)
    cfg = parse_config(base(), ["mesh.ste_amplitude_um=[1.0]", "mesh.ste_phase_deg=[90]"])
    assert cfg.mesh.ste_phase_rad == pytest.approx((math.pi / 2,))


def test_to_dict_round_trip():
    for name in ("paper_table1.toml", "low_speed_nltv.toml", "backlash.toml", "bearings.toml"):
        cfg = load_config(EXAMPLES / name)
        again = parse_config(cfg.to_dict())
        for section in dataclasses.fields(RunConfig):
            if getattr(cfg, section.name) is None:  # an optional section left out ([bearings], [shafts])
                assert getattr(again, section.name) is None, section.name
                continue
            a = dataclasses.asdict(getattr(cfg, section.name))
            b = dataclasses.asdict(getattr(again, section.name))
            assert a.keys() == b.keys()
            for key in a:
                if a[key] is None or isinstance(a[key], str):
                    assert a[key] == b[key], (section.name, key)
                else:
                    assert a[key] == pytest.approx(b[key], rel=1e-12), (section.name, key)
    assert load_config(EXAMPLES / "paper_table1.toml").to_dict()["gear"]["module_mm"] == (
        pytest.approx(3.175)
    )


def test_dataclasses_check_invariants_when_built_directly():
    with pytest.raises(ConfigError):
        SolverConfig(harmonics=200, time_samples=256)
    with pytest.raises(ConfigError):
        MeshConfig(k_max_N_per_m=7e8)
    with pytest.raises(ConfigError):
        GearConfig(
            teeth_pinion=25,
            teeth_gear=31,
            module_m=3e-3,
            contact_ratio=1.4,
            addendum_coefficient=1.0,
            inertia_pinion_kgm2=1e-3,
            inertia_gear_kgm2=1e-3,
        )


# ----------------------------------------------------------------------------- overrides


@pytest.mark.parametrize(
    "text, expected",
    [
        ("solver.harmonics=32", 32),
        ("solver.harmonics = 32", 32),
        ("solver.harmonics=auto", "auto"),
        ('friction.law="arctan"', "arctan"),
        ("friction.law=arctan", "arctan"),
        ("friction.law=kelley-lemanski", "kelley-lemanski"),
        ("mesh.ste_amplitude_um=[1.0,0.5]", [1.0, 0.5]),
        ("mesh.damping_ratio=0.02", 0.02),
        ("mesh.damping_ratio=1e-3", 1e-3),
        ("map.scheduler=tcp://host:8786", "tcp://host:8786"),
        ("solver.harmonics=1\nx = 2", "1\nx = 2"),
    ],
)
def test_override_values_are_typed(text, expected):
    lhs = text.split("=", 1)[0].strip()
    section, key = lhs.split(".")
    value = apply_overrides(base(), [text])[section][key]
    assert value == expected and type(value) is type(expected)


def test_override_nan_is_float_then_rejected():
    value = apply_overrides(base(), ["mesh.damping_ratio=nan"])["mesh"]["damping_ratio"]
    assert math.isnan(value)
    assert error_of(base(), ["mesh.damping_ratio=nan"]).key == "mesh.damping_ratio"


def test_overrides_do_not_mutate_input_and_apply():
    data = base()
    cfg = parse_config(data, ["solver.harmonics=16", "friction.law=arctan", "simulate.cycles=10"])
    assert data == BASE
    assert (cfg.solver.harmonics, cfg.friction.law, cfg.simulate.cycles) == (16, "arctan", 10)


@pytest.mark.parametrize("text", ["harmonics=32", "solver.harmonics", "=3", ".x=1", "solver.=1"])
def test_malformed_override(text):
    err = error_of(base(), [text])
    assert (err.key, err.value, err.allowed) == ("--set", text, "section.key=value")


def test_override_into_non_table_section():
    data = base()
    data["solver"] = 3
    assert error_of(data, ["solver.harmonics=2"]).key == "solver"


# ----------------------------------------------------------------------------- bad configs


def mutate(path, value):
    data = base()
    section, key = path.split(".")
    data[section][key] = value
    return data


@pytest.mark.parametrize(
    "path, value",
    [
        ("gear.teeth_pinion", 0),
        ("gear.teeth_pinion", 4),
        ("gear.teeth_pinion", 25.0),
        ("gear.teeth_gear", True),
        ("gear.teeth_gear", "31"),
        ("gear.module_mm", -1.0),
        ("gear.module_mm", 0),
        ("gear.module_mm", float("inf")),
        ("gear.pressure_angle_deg", 45.0),
        ("gear.contact_ratio", 2.5),
        ("gear.contact_ratio", 1.0),
        ("gear.face_width_mm", float("nan")),
        ("gear.inertia_pinion_kgm2", -1e-3),
        ("gear.inertia_gear_kgm2", False),
        ("mesh.k_max_MN_per_m", -720.0),
        ("mesh.k_max_MN_per_m", 1e305),
        ("mesh.k_mean_MN_per_m", 800.0),
        ("mesh.damping_ratio", 1.0),
        ("mesh.damping_ratio", -0.1),
        ("mesh.damping_model", "viscous"),
        ("mesh.backlash_um", -1.0),
        ("mesh.ste_amplitude_um", 1.0),
        ("mesh.ste_amplitude_um", [1.0, -1.0]),
        ("mesh.ste_phase_deg", [1.0]),
        ("load.torque_pinion_Nm", 0.0),
        ("friction.law", "stribeck"),
        ("friction.law", 1),
        ("friction.mu0", 1.5),
        ("friction.formulation", "C"),
        ("friction.model", "NL"),
        ("boundary.output", "free"),
        ("boundary.stiffness_ratio", 1.0),
        ("solver.harmonics", 0),
        ("solver.harmonics", 4096),
        ("solver.harmonics", 32.0),
        ("solver.harmonics", "many"),
        ("solver.subharmonic", 3),
        ("solver.time_samples", 8),
        ("solver.time_samples", 60),  # < 2*32*1+2
        ("solver.tolerance", 0.0),
        ("solver.tolerance", 0.1),
        ("solver.max_iterations", 0),
        ("simulate.cycles", 1),
        ("simulate.rtol", 1.0),
        ("sweep.speed_rpm_stop", 1000.0),  # equal to start
        ("sweep.speed_rpm_start", -1.0),
        ("sweep.max_points", 1),
        ("sweep.step_rpm", 0.0),
        ("map.contact_ratio_stop", 2.0),
        ("map.speed_steps", 0),
        ("map.scheduler", 8786),
    ],
)
def test_bad_value_names_the_key(path, value):
    err = error_of(mutate(path, value))
    assert err.key.startswith(path)
    assert "\n" not in str(err)


def test_time_samples_checked_against_harmonics_override():
    err = error_of(base(), ["solver.harmonics=200"])
    assert err.key == "solver.time_samples" and "402" in err.allowed


@pytest.mark.parametrize(
    "section, key, other",
    [
        ("gear", "module_mm", "center_distance_mm"),
        ("gear", "contact_ratio", "addendum_coefficient"),
        ("mesh", "k_mean_MN_per_m", "k_min_MN_per_m"),
    ],
)
def test_mutually_exclusive_keys(section, key, other):
    data = base()
    data[section][other] = data[section][key]
    err = error_of(data)
    assert err.key == f"{section}.{other}" and "not both" in err.allowed


@pytest.mark.parametrize(
    "section, key",
    [("gear", "teeth_pinion"), ("gear", "module_mm"), ("gear", "inertia_gear_kgm2"),
     ("mesh", "k_max_MN_per_m"), ("mesh", "k_mean_MN_per_m"), ("load", "torque_pinion_Nm")],
)
def test_missing_required_key(section, key):
    data = base()
    del data[section][key]
    err = error_of(data)
    assert err.key == f"{section}.{key}" and err.allowed.startswith("required")


@pytest.mark.parametrize("section", ["gear", "mesh", "load"])
def test_missing_required_section(section):
    data = base()
    del data[section]
    assert error_of(data).key == section


def test_unknown_key_lists_allowed_keys():
    err = error_of(mutate("gear.modul_mm", 3.0))
    assert err.key == "gear.modul_mm"
    assert "module_mm" in err.allowed and "teeth_pinion" in err.allowed


def test_unknown_section_lists_sections():
    data = base()
    data["solverr"] = {}
    err = error_of(data)
    assert err.key == "solverr" and "[solver]" in err.allowed


def test_file_errors(tmp_path):
    with pytest.raises(ConfigError) as info:
        load_config(tmp_path / "missing.toml")
    assert info.value.key == "config" and "readable" in info.value.allowed
    bad = tmp_path / "bad.toml"
    bad.write_text("[gear\nteeth_pinion = 25\n")
    with pytest.raises(ConfigError) as info:
        load_config(bad)
    assert info.value.key == "config" and "\n" not in str(info.value)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ConfigError):
        load_config(binary)
    with pytest.raises(ConfigError):
        load_config(tmp_path)  # a directory


# ----------------------------------------------------------------------------- properties

_junk = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1, 2, 5, 1e308, -1e308, 5e-324, 1.5, 2048, 2049, "auto"]),
    st.text(max_size=12),
    st.sampled_from(["coulomb", "arctan", "A", "b", "nltv", "LTI", "spring", "none"]),
    st.lists(st.floats(allow_nan=True), max_size=3),
    st.dictionaries(st.text(max_size=4), st.integers(), max_size=2),
)
_paths = [(s, k) for s, table in BASE.items() for k in table] + [
    ("gear", "center_distance_mm"),
    ("gear", "addendum_coefficient"),
    ("mesh", "k_min_MN_per_m"),
    ("mesh", "ste_amplitude_um"),
    ("mesh", "ste_phase_deg"),
    ("mesh", "backlash_um"),
    ("friction", "v0_m_per_s"),
    ("sweep", "step_rpm"),
    ("map", "scheduler"),
    ("gear", "bogus"),
    ("extra", "key"),
]
_edit = st.one_of(
    st.tuples(st.just("set"), st.sampled_from(_paths), _junk),
    st.tuples(st.just("del"), st.sampled_from(_paths), st.none()),
    st.tuples(st.just("section"), st.sampled_from(list(BASE) + ["x"]), _junk),
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_edit, min_size=1, max_size=4))
def test_mangled_configs_only_raise_config_error(edits):
    data = base()
    for op, target, value in edits:
        if op == "section":
            data[target] = value
            continue
        section, key = target
        table = data.setdefault(section, {})
        if not isinstance(table, dict):
            continue
        if op == "set":
            table[key] = value
        else:
            table.pop(key, None)
    try:
        cfg = parse_config(data)
    except ConfigError as err:
        assert "\n" not in str(err)
        assert isinstance(err.key, str) and err.key
        return
    # whatever was accepted is finite and within the documented ranges
    assert isinstance(cfg, RunConfig)
    assert cfg.gear.teeth_pinion >= 5 and cfg.gear.module_m > 0
    assert 0 < (cfg.mesh.k_mean_N_per_m or cfg.mesh.k_min_N_per_m) <= cfg.mesh.k_max_N_per_m
    for section in dataclasses.fields(cfg):
        part = getattr(cfg, section.name)
        if part is None:  # an optional section left out
            continue
        flags = {f.name for f in dataclasses.fields(part) if str(f.type).startswith("bool")}  # true/false keys
        for name, value in dataclasses.asdict(part).items():
            if isinstance(value, float):
                assert math.isfinite(value), (section.name, name)
            assert name in flags or not isinstance(value, bool), (section.name, name)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.text(max_size=30), max_size=3))
def test_random_overrides_only_raise_config_error(overrides):
    try:
        parse_config(base(), overrides)
    except ConfigError as err:
        assert "\n" not in str(err)


@settings(max_examples=100, deadline=None)
@given(
    st.sampled_from([p for p in _paths if p[0] in BASE]),
    st.one_of(st.floats(), st.integers(), st.text(max_size=8), st.booleans()),
)
def test_override_text_forms_only_raise_config_error(path, value):
    shown = repr(value) if isinstance(value, str) else str(value)
    text = f"{path[0]}.{path[1]}={shown}"
    try:
        parse_config(base(), [text])
    except ConfigError:
        pass
