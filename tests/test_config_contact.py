"""Config keys of MODEL.md section 9 (profile shift, pair-stiffness models, [profile]) and
``build_tooth_contact``: defaults, wiring into the library, one-line errors for bad input."""

import copy
import dataclasses
import math

import numpy as np
import pytest

from hbgear.build import build_geometry, build_model, build_tooth_contact
from hbgear.config import RunConfig, load_config, parse_config
from hbgear.errors import ConfigError
from hbgear.gear.contact import (
    RectangularMeshStiffness,
    TablePairStiffness,
    iso6336_stiffness,
    potential_energy_pair_stiffness,
)
from hbgear.gear.geometry import involute

REFERENCE = {
    "gear": {"teeth_pinion": 25, "teeth_gear": 31, "module_mm": 3.175, "contact_ratio": 1.433,
             "face_width_mm": 20.0, "inertia_pinion_kgm2": 1.0594e-3, "inertia_gear_kgm2": 2.5047e-3},
    "mesh": {"k_max_MN_per_m": 720.0, "k_mean_MN_per_m": 568.0},
    "load": {"torque_pinion_Nm": 226.0},
}
ISO = {**REFERENCE, "mesh": {"stiffness_model": "iso6336"}}
KHK = {  # KHK Gear Technical Reference, profile-shifted example: m = 3, z = 12/24, x = 0.6/0.36
    "gear": {"teeth_pinion": 12, "teeth_gear": 24, "module_mm": 3.0, "profile_shift_pinion": 0.6,
             "profile_shift_gear": 0.36, "tip_shortening": True, "inertia_pinion_kgm2": 1e-4,
             "inertia_gear_kgm2": 1e-3},
    "mesh": {"stiffness_model": "iso6336"},
    "load": {"torque_pinion_Nm": 50.0},
}
PE = {**REFERENCE, "mesh": {"stiffness_model": "potential_energy"},
      "gear": {**REFERENCE["gear"], "bore_diameter_pinion_mm": 12.5, "bore_diameter_gear_mm": 15.0}}


def edit(data, **sections):
    """A deep copy of `data` with keys set (value) or removed (None) per section."""
    out = copy.deepcopy(data)
    for section, keys in sections.items():
        table = out.setdefault(section, {})
        for key, value in keys.items():
            if value is None:
                table.pop(key, None)
            else:
                table[key] = value
    return out


def error_of(data, build=False):
    with pytest.raises(ConfigError) as info:
        cfg = parse_config(data)
        if build:
            build_tooth_contact(cfg)
    assert "\n" not in str(info.value)
    return info.value


# ----------------------------------------------------------------------------- defaults, limits


def test_defaults_keep_the_rectangular_model_and_no_relief():
    cfg = parse_config(REFERENCE)
    assert cfg.mesh.stiffness_model == "rectangular"
    assert (cfg.gear.profile_shift_pinion, cfg.gear.profile_shift_gear, cfg.gear.tip_shortening) == (0.0, 0.0, False)
    assert cfg.gear.working_center_distance_m is None and not cfg.profile.relieved
    assert cfg.mesh.youngs_modulus_Pa == 206e9 and cfg.mesh.poisson_ratio == 0.3
    assert (cfg.mesh.rack_dedendum_coefficient, cfg.mesh.rack_tip_radius_coefficient) == (1.25, 0.38)
    contact = build_tooth_contact(cfg)
    model = build_model(cfg)
    assert contact.pair_stiffness == RectangularMeshStiffness(720e6, model.k_min_N_per_m)
    assert contact.iso6336 is None and contact.torque_pinion_Nm == 226.0
    xi = np.linspace(0.0, 0.02, 7)
    assert np.all(contact.modification.deviation(contact.geometry, xi) == 0.0)


@pytest.mark.parametrize("gear", [{"contact_ratio": None, "addendum_coefficient": 0.9}, {}])
def test_zero_profile_shift_is_bit_identical(gear):
    plain = parse_config(edit(REFERENCE, gear=gear))
    zero = parse_config(edit(REFERENCE, gear={**gear, "profile_shift_pinion": 0.0, "profile_shift_gear": 0,
                                              "tip_shortening": False}))
    assert build_geometry(zero.gear) == build_geometry(plain.gear)
    a, b = build_model(zero), build_model(plain)
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, f.name


# ----------------------------------------------------------------------------- profile shift


def test_profile_shift_reproduces_the_khk_example():
    # KHK: inv(phi_w) = 0.034316, phi_w = 26.0886 deg, a = 56.4999 mm, d_a = 44.840 / 79.400 mm, eps = 1.20
    pair = build_geometry(parse_config(KHK).gear)
    assert involute(pair.working_pressure_angle_rad) == pytest.approx(0.034316, abs=5e-7)
    assert math.degrees(pair.working_pressure_angle_rad) == pytest.approx(26.0886, abs=5e-5)
    assert pair.center_distance_m * 1e3 == pytest.approx(56.4999, abs=5e-5)
    assert (2e3 * pair.tip_radius_pinion_m, 2e3 * pair.tip_radius_gear_m) == pytest.approx((44.840, 79.400),
                                                                                          abs=5e-4)
    assert pair.contact_ratio == pytest.approx(1.20, abs=5e-3)
    # the same pair at the imposed 56.500 mm (bolsover.com table): phi_w = 26.0888 deg
    imposed = build_geometry(parse_config(edit(KHK, gear={"center_distance_mm": 56.5})).gear)
    assert imposed.center_distance_m == 56.5e-3
    assert math.degrees(imposed.working_pressure_angle_rad) == pytest.approx(26.0888, abs=5e-5)


@pytest.mark.parametrize(
    "changes, key",
    [
        ({"contact_ratio": 1.4}, "gear.contact_ratio"),  # the addendum is solved for unshifted pairs only
        ({"module_mm": None, "center_distance_mm": 56.5}, "gear.center_distance_mm"),  # module or a_w?
        ({"center_distance_mm": 56.0}, "gear.center_distance_mm"),  # below zero backlash: interference
        ({"center_distance_mm": 60.0}, "gear.tip_shortening"),  # x1 + x2 - y < 0 would lengthen the tips
        ({"profile_shift_pinion": -0.9}, "gear.profile_shift_pinion"),  # the gear tip passes T1
        ({"profile_shift_pinion": 2.0}, "gear.profile_shift_pinion"),
        ({"profile_shift_gear": "0.3"}, "gear.profile_shift_gear"),
        ({"tip_shortening": 1}, "gear.tip_shortening"),
    ],
)
def test_shift_combinations_that_are_rejected(changes, key):
    err = error_of(edit(KHK, gear=changes), build=True)
    assert err.key == key


def test_module_and_center_distance_without_shift_stay_exclusive():
    err = error_of(edit(REFERENCE, gear={"center_distance_mm": 88.9}))
    assert err.key == "gear.center_distance_mm" and "not both" in err.allowed


def test_contact_ratio_override_is_refused_for_a_shifted_pair():
    with pytest.raises(ConfigError) as info:
        build_geometry(parse_config(KHK).gear, contact_ratio=1.3)
    assert info.value.key == "gear.profile_shift_pinion"


# ----------------------------------------------------------------------------- stiffness models


def test_iso6336_numbers_and_line_load_factor():
    cfg = parse_config(edit(ISO, mesh={"blank_factor": 0.9, "youngs_modulus_GPa": 210.0}))
    for torque in (226.0, 40.0):  # 285 N/mm (f_w = 1) and 50 N/mm
        contact = build_tooth_contact(cfg, torque)
        pair = contact.geometry
        line_load = torque / (3.175e-3 * 25 / 2) / 20.0  # F_t / b [N/mm], F_t at the reference circle
        expected = iso6336_stiffness((25, 31), (0.0, 0.0), pair.contact_ratio, rack_dedendum_coefficient=(1.25, 1.25),
                                     blank_factor=0.9, youngs_modulus_Pa=(210e9, 210e9), line_load_N_per_mm=line_load)
        assert contact.iso6336 == expected
        assert expected.line_load_factor == (1.0 if line_load >= 100 else (line_load / 100) ** 0.25)
        assert expected.basic_rack_factor == pytest.approx(0.975, rel=1e-15)  # ISO 53 profile A rack
        assert contact.pair_stiffness.peak_N_per_m == pytest.approx(expected.c_prime_N_per_mm_um * 20.0 * 1e6,
                                                                    rel=1e-15)


def test_iso6336_uses_the_profile_shift():
    contact = build_tooth_contact(parse_config(KHK))
    assert contact.iso6336 == iso6336_stiffness((12, 24), (0.6, 0.36), contact.geometry.contact_ratio,
                                                rack_dedendum_coefficient=(1.25, 1.25),
                                                line_load_N_per_mm=50.0 / 18e-3 / 20.0)


def test_potential_energy_from_the_config():
    contact = build_tooth_contact(parse_config(PE))
    expected = potential_energy_pair_stiffness(contact.geometry, 0.020, 206e9, 0.3, (6.25e-3, 7.5e-3),
                                               rack_dedendum_coefficient=1.25, rack_tip_radius_coefficient=0.38)
    assert contact.pair_stiffness == expected


@pytest.mark.parametrize(
    "data, key",
    [
        (edit(PE, gear={"bore_diameter_pinion_mm": 60.0}), "gear.bore_diameter_pinion_mm"),  # h_f < 1.4
        (edit(PE, gear={"bore_diameter_gear_mm": 5.0}), "gear.bore_diameter_gear_mm"),  # h_f > 7
        (edit(PE, mesh={"rack_tip_radius_coefficient": 0.48}), "mesh.rack_tip_radius_coefficient"),  # no tip flat
        (edit(PE, gear={"teeth_gear": 60, "contact_ratio": None}), "mesh.stiffness_model"),  # root outside base
    ],
)
def test_potential_energy_assumptions_are_checked(data, key):
    assert error_of(data, build=True).key == key


@pytest.mark.parametrize(
    "data, key, model",
    [
        (edit(ISO, mesh={"k_max_MN_per_m": 720.0}), "mesh.k_max_MN_per_m", "iso6336"),
        (edit(ISO, mesh={"poisson_ratio": 0.3}), "mesh.poisson_ratio", "iso6336"),
        (edit(ISO, mesh={"pair_stiffness_file": "p.csv"}), "mesh.pair_stiffness_file", "iso6336"),
        (edit(ISO, gear={"bore_diameter_pinion_mm": 12.5}), "gear.bore_diameter_pinion_mm", "iso6336"),
        (edit(REFERENCE, mesh={"youngs_modulus_GPa": 206.0}), "mesh.youngs_modulus_GPa", "rectangular"),
        (edit(REFERENCE, mesh={"blank_factor": 1.0}), "mesh.blank_factor", "rectangular"),
        (edit(PE, mesh={"blank_factor": 1.0}), "mesh.blank_factor", "potential_energy"),
        (edit(ISO, mesh={"stiffness_model": "pair_table", "pair_stiffness_file": "p.csv", "youngs_modulus_GPa": 1.0}),
         "mesh.youngs_modulus_GPa", "pair_table"),
    ],
)
def test_keys_that_do_not_apply_to_the_model(data, key, model):
    err = error_of(data)
    assert err.key == key and f"'{model}'" in err.allowed


@pytest.mark.parametrize(
    "data, key",
    [
        (edit(REFERENCE, mesh={"k_max_MN_per_m": None}), "mesh.k_max_MN_per_m"),
        (edit(ISO, mesh={"stiffness_model": "pair_table"}), "mesh.pair_stiffness_file"),
        (edit(PE, gear={"bore_diameter_gear_mm": None}), "gear.bore_diameter_gear_mm"),
    ],
)
def test_keys_a_model_requires(data, key):
    err = error_of(data)
    assert err.key == key and err.allowed.startswith("required")


@pytest.mark.parametrize(
    "mesh",
    [{"stiffness_model": "fem"}, {"youngs_modulus_GPa": 0.0}, {"youngs_modulus_GPa": "steel"},
     {"rack_dedendum_coefficient": 0.9}, {"blank_factor": 1.2}, {"blank_factor": 0.0}],
)
def test_bad_model_values(mesh):
    assert error_of(edit(ISO, mesh=mesh)).key == f"mesh.{next(iter(mesh))}"


def test_dynamic_model_takes_the_per_pair_stiffness():
    """A per-pair stiffness model builds the per-pair mesh (proportional damping, its own k_mean)."""
    from hbgear.gear.mesh import PairContactMesh

    model = build_model(parse_config(ISO))
    assert isinstance(model.mesh, PairContactMesh) and model.damping_model == "proportional"
    assert model.k_min_N_per_m < model.k_mean_N_per_m < model.k_max_N_per_m


# ----------------------------------------------------------------------------- pair table


def test_pair_table_is_read_relative_to_the_config_file(tmp_path, monkeypatch):
    pair = build_geometry(parse_config(REFERENCE).gear)
    path_mm = 1e3 * (pair.contact_end_m - pair.contact_start_m)
    folder = tmp_path / "configs"
    folder.mkdir()
    (folder / "pair.csv").write_text(f"position_mm,stiffness_MN_per_m\n0,200\n{path_mm / 2},260\n{path_mm},210\n")
    config = folder / "c.toml"
    config.write_text(
        "[gear]\nteeth_pinion = 25\nteeth_gear = 31\nmodule_mm = 3.175\ncontact_ratio = 1.433\n"
        "inertia_pinion_kgm2 = 1e-3\ninertia_gear_kgm2 = 2e-3\n"
        '[mesh]\nstiffness_model = "pair_table"\npair_stiffness_file = "pair.csv"\n[load]\ntorque_pinion_Nm = 100.0\n'
    )
    monkeypatch.chdir(tmp_path)  # not the config's directory
    cfg = load_config(config)
    assert cfg.mesh.pair_stiffness_file == folder / "pair.csv"
    stiffness = build_tooth_contact(cfg).pair_stiffness
    assert isinstance(stiffness, TablePairStiffness)
    assert stiffness.stiffness_N_per_m == (200e6, 260e6, 210e6)
    (folder / "pair.csv").unlink()
    with pytest.raises(ConfigError) as info:
        build_tooth_contact(load_config(config))
    assert info.value.key == "mesh.pair_stiffness_file" and "pair.csv" in str(info.value.value)


# ----------------------------------------------------------------------------- [profile]


def test_profile_keys_reach_the_library():
    cfg = parse_config(edit(ISO, profile={"pinion_tip_relief_um": 20.0, "pinion_tip_relief_length_mm": 4.0,
                                          "gear_root_relief_um": 5.0, "gear_root_relief_length_mm": 1.5,
                                          "shape": "parabolic"}))
    assert cfg.profile.relieved == ("pinion_tip_relief_um", "gear_root_relief_um")
    contact = build_tooth_contact(cfg)
    pinion, gear = contact.modification.pinion, contact.modification.gear
    assert pinion.tip_relief_m == pytest.approx(20e-6, rel=1e-15) and pinion.tip_length_m == pytest.approx(4e-3)
    assert gear.root_relief_m == pytest.approx(5e-6, rel=1e-15) and gear.root_length_m == pytest.approx(1.5e-3)
    assert pinion.shape == gear.shape == "parabolic"
    # at the end of contact the pinion tip is relieved by the full amount, the gear root (also there) by its own
    e = contact.modification.deviation(contact.geometry, contact.geometry.contact_end_m)
    assert e == pytest.approx(25e-6, rel=1e-12)


@pytest.mark.parametrize(
    "profile, key",
    [
        ({"pinion_tip_relief_um": -1.0, "pinion_tip_relief_length_mm": 1.0}, "profile.pinion_tip_relief_um"),
        ({"gear_tip_relief_um": 10.0}, "profile.gear_tip_relief_length_mm"),  # an amount needs a length
        ({"gear_tip_relief_um": 10.0, "gear_tip_relief_length_mm": 14.0}, "profile.gear_tip_relief_length_mm"),
        ({"pinion_root_relief_um": float("nan"), "pinion_root_relief_length_mm": 1.0},
         "profile.pinion_root_relief_um"),
        ({"shape": "cubic"}, "profile.shape"),
        ({"tip_relief_um": 10.0}, "profile.tip_relief_um"),
    ],
)
def test_bad_profile_values(profile, key):
    assert error_of(edit(ISO, profile=profile), build=True).key == key


def test_relief_needs_a_per_pair_model():
    err = error_of(edit(REFERENCE, profile={"gear_tip_relief_um": 10.0, "gear_tip_relief_length_mm": 4.0}))
    assert err.key == "profile.gear_tip_relief_um" and "'rectangular'" in err.allowed
    # zeros are no relief, allowed with any model
    parse_config(edit(REFERENCE, profile={"gear_tip_relief_um": 0.0, "gear_tip_relief_length_mm": 4.0}))


# ----------------------------------------------------------------------------- provenance


@pytest.mark.parametrize("data", [
    REFERENCE,
    edit(ISO, profile={"pinion_tip_relief_um": 24.0, "pinion_tip_relief_length_mm": 4.06, "shape": "parabolic"},
         mesh={"blank_factor": 0.8, "rack_dedendum_coefficient": 1.4}),
    edit(KHK, gear={"center_distance_mm": 56.5}),
    edit(PE, mesh={"poisson_ratio": 0.28, "rack_tip_radius_coefficient": 0.3}),
    edit(ISO, mesh={"stiffness_model": "pair_table", "pair_stiffness_file": "/data/pair.csv"}),
])
def test_to_dict_carries_the_new_keys_and_round_trips(data):
    cfg = parse_config(data)
    again = parse_config(cfg.to_dict())
    for section in dataclasses.fields(RunConfig):
        if getattr(cfg, section.name) is None:  # an optional section left out ([bearings], [shafts])
            assert getattr(again, section.name) is None, section.name
            continue
        a, b = dataclasses.asdict(getattr(cfg, section.name)), dataclasses.asdict(getattr(again, section.name))
        assert a.keys() == b.keys()
        for key in a:
            if isinstance(a[key], float):
                assert a[key] == pytest.approx(b[key], rel=1e-12), (section.name, key)
            else:
                assert a[key] == b[key], (section.name, key)
    out = cfg.to_dict()
    assert out["mesh"]["stiffness_model"] == cfg.mesh.stiffness_model
    assert set(out["profile"]) >= {"pinion_tip_relief_um", "gear_tip_relief_length_mm", "shape"}
    assert {"profile_shift_pinion", "profile_shift_gear", "tip_shortening"} <= set(out["gear"])

