"""Pair stiffness models: constant, user table (loader checks and round trip)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hbgear.errors import ConfigError
from hbgear.gear.contact import ConstantPairStiffness, Iso6336PairStiffness, load_pair_stiffness_table
from hbgear.gear.contact.stiffness import TABLE_COVERAGE_TOLERANCE
from hbgear.gear.geometry import GearPair

jax.config.update("jax_enable_x64", True)

PAIR = GearPair.with_contact_ratio(25, 31, 3.175e-3, math.radians(20.0), 1.433)
PATH_MM = (PAIR.contact_end_m - PAIR.contact_start_m) * 1e3
KEY = "mesh.pair_stiffness_file"


def write(tmp_path, text, name="pair.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def list_of(values):
    return [v.item() if isinstance(v, np.generic) else v for v in values]


def table_text(positions_mm, stiffness, header="position_mm,stiffness_MN_per_m"):
    return header + "\n" + "".join(f"{x!r},{k!r}\n" for x, k in zip(list_of(positions_mm), list_of(stiffness)))


def test_constant_numpy_and_jax():
    k = ConstantPairStiffness(3.6e8)
    xi = np.linspace(0, 0.01, 5)
    assert np.all(k.stiffness(xi) == 3.6e8)
    assert np.all(np.asarray(jax.jit(lambda x: k.stiffness(x, jnp))(xi)) == 3.6e8)


def test_table_round_trip_and_linear_between_rows(tmp_path):
    iso, _ = Iso6336PairStiffness.from_geometry(PAIR, 0.020)
    positions = np.linspace(0.0, PATH_MM, 41)
    values = iso.stiffness(positions * 1e-3) * 1e-6
    table = load_pair_stiffness_table(write(tmp_path, table_text(positions, values)), PAIR)
    np.testing.assert_allclose(table.stiffness(positions * 1e-3), values * 1e6, rtol=1e-15)
    mid = 0.5 * (positions[:-1] + positions[1:]) * 1e-3
    np.testing.assert_allclose(table.stiffness(mid), 0.5 * (values[:-1] + values[1:]) * 1e6, rtol=1e-14)
    # held at the end values just outside, and the same under jax
    assert table.stiffness(-1e-4) == values[0] * 1e6
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: table.stiffness(x, jnp))(mid)), table.stiffness(mid),
                               rtol=1e-15)


def test_roll_angle_column_and_column_order(tmp_path):
    positions = np.linspace(0.0, PATH_MM, 11)
    values = 200.0 + 30.0 * np.sin(positions)
    by_position = load_pair_stiffness_table(write(tmp_path, table_text(positions, values)), PAIR)
    roll_deg = np.degrees((positions * 1e-3 + PAIR.contact_start_m) / PAIR.base_radius_pinion_m)
    by_angle = load_pair_stiffness_table(
        write(tmp_path, table_text(roll_deg, values, "roll_angle_deg,stiffness_MN_per_m"), "a.csv"), PAIR)
    np.testing.assert_allclose(by_angle.positions_m, by_position.positions_m, rtol=1e-12, atol=1e-15)
    swapped = "stiffness_MN_per_m,position_mm\n" + "".join(f"{k!r},{x!r}\n" for x, k in zip(positions.tolist(), values.tolist()))
    by_swapped = load_pair_stiffness_table(write(tmp_path, swapped, "s.csv"), PAIR)
    assert by_swapped == by_position


GOOD = np.linspace(0.0, PATH_MM, 5)
BAD_TABLES = {
    "empty": ("", "empty file"),
    "header misspelled": ("position,stiffness_MN_per_m\n0,1\n20,1\n", "header"),
    "extra column": ("position_mm,stiffness_MN_per_m,x\n0,1,2\n20,1,2\n", "header"),
    "one column": ("position_mm\n0\n", "header"),
    "two positions": ("position_mm,roll_angle_deg\n0,1\n20,1\n", "header"),
    "not a number": (table_text(GOOD, [200, 200, "abc", 200, 200]).replace("'abc'", "abc"), "finite numbers"),
    "nan": (table_text(GOOD, [200, 200, float("nan"), 200, 200]), "finite numbers"),
    "inf position": (table_text([0.0, 1.0, math.inf], [200, 200, 200]), "finite numbers"),
    "zero stiffness": (table_text(GOOD, [200, 200, 0.0, 200, 200]), "stiffness_MN_per_m > 0"),
    "negative stiffness": (table_text(GOOD, [200, -5.0, 200, 200, 200]), "stiffness_MN_per_m > 0"),
    "repeated position": (table_text([0.0, 3.0, 3.0, PATH_MM], [200] * 4), "strictly increasing"),
    "decreasing position": (table_text([0.0, 5.0, 4.0, PATH_MM], [200] * 4), "strictly increasing"),
    "one row": (table_text([0.0], [200]), "at least 2 data rows"),
    "three fields": (table_text(GOOD, [200] * 5) + "1,2,3\n", "3 fields"),
    "starts late": (table_text([0.2, PATH_MM], [200, 200]), "covering the path"),
    "ends early": (table_text([0.0, 0.97 * PATH_MM], [200, 200]), "covering the path"),
}


@pytest.mark.parametrize("case", sorted(BAD_TABLES))
def test_bad_table_raises_config_error(tmp_path, case):
    text, fragment = BAD_TABLES[case]
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_pair_stiffness_table(path, PAIR)
    assert info.value.key == KEY
    assert str(path) in str(info.value.value)
    assert "\n" not in str(info.value)
    assert fragment in str(info.value)


def test_missing_file_and_directory(tmp_path):
    for path in (tmp_path / "nope.csv", tmp_path):
        with pytest.raises(ConfigError) as info:
            load_pair_stiffness_table(path, PAIR)
        assert info.value.key == KEY and "readable" in info.value.allowed


def test_coverage_tolerance_edges(tmp_path):
    inside = TABLE_COVERAGE_TOLERANCE * PATH_MM * 0.9
    load_pair_stiffness_table(write(tmp_path, table_text([inside, PATH_MM - inside], [200, 210])), PAIR)
    outside = TABLE_COVERAGE_TOLERANCE * PATH_MM * 1.1
    with pytest.raises(ConfigError, match="covering the path"):
        load_pair_stiffness_table(write(tmp_path, table_text([outside, PATH_MM], [200, 210]), "b.csv"), PAIR)
