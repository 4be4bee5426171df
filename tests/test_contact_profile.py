"""Tip and root relief along the line of action, and the checked constructor."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hbgear.errors import ConfigError
from hbgear.gear.contact import FlankRelief, ProfileModification, profile_modification
from hbgear.gear.geometry import GearPair

jax.config.update("jax_enable_x64", True)

PAIR = GearPair.with_contact_ratio(25, 31, 3.175e-3, math.radians(20.0), 1.433)
XA, XE = PAIR.contact_start_m, PAIR.contact_end_m
C, LA = 10e-6, 2e-3


@pytest.mark.parametrize(("shape", "half"), [("linear", 0.5), ("parabolic", 0.25)])
def test_pinion_tip_relief_grows_to_the_end_of_contact(shape, half):
    mod = ProfileModification(pinion=FlankRelief(C, LA, shape=shape))
    e = mod.deviation(PAIR, np.array([XA, XE - LA - 1e-6, XE - LA, XE - 0.5 * LA, XE]))
    np.testing.assert_allclose(e, [0.0, 0.0, 0.0, half * C, C], rtol=1e-12, atol=1e-20)


@pytest.mark.parametrize(("shape", "half"), [("linear", 0.5), ("parabolic", 0.25)])
def test_gear_tip_relief_grows_towards_the_start_of_contact(shape, half):
    mod = ProfileModification(gear=FlankRelief(C, LA, shape=shape))
    e = mod.deviation(PAIR, np.array([XA, XA + 0.5 * LA, XA + LA, XE]))
    np.testing.assert_allclose(e, [C, half * C, 0.0, 0.0], rtol=1e-12, atol=1e-20)


def test_root_relief_at_the_other_ends_and_composite_sum():
    pinion = FlankRelief(C, LA, root_relief_m=3e-6, root_length_m=1e-3)
    gear = FlankRelief(4e-6, LA, root_relief_m=2e-6, root_length_m=1e-3)
    xi = np.linspace(XA, XE, 101)
    both = ProfileModification(pinion, gear).deviation(PAIR, xi)
    alone = ProfileModification(pinion).deviation(PAIR, xi) + ProfileModification(gear=gear).deviation(PAIR, xi)
    np.testing.assert_allclose(both, alone, rtol=1e-15)
    # pinion root at x_A with the gear tip, gear root at x_E with the pinion tip
    assert ProfileModification(FlankRelief(root_relief_m=3e-6, root_length_m=1e-3)).deviation(PAIR, XA) \
        == pytest.approx(3e-6, rel=1e-12)
    assert ProfileModification(gear=FlankRelief(root_relief_m=2e-6, root_length_m=1e-3)).deviation(PAIR, XE) \
        == pytest.approx(2e-6, rel=1e-12)
    assert ProfileModification().deviation(PAIR, xi).max() == 0.0


def test_jax_matches_numpy():
    mod = ProfileModification(FlankRelief(C, LA, shape="parabolic"), FlankRelief(C, LA, 1e-6, 1e-3))
    xi = np.linspace(XA, XE, 64)
    # the ramps difference positions (~x_E) at slope C/L: rounding is ~eps x_E C / L absolute
    atol = 4 * np.finfo(float).eps * XE * C / 1e-3
    np.testing.assert_allclose(np.asarray(jax.jit(lambda x: mod.deviation(PAIR, x, jnp))(xi)),
                               mod.deviation(PAIR, xi), rtol=1e-15, atol=atol)


def test_constructor_units():
    mod = profile_modification(PAIR, pinion_tip_relief_um=12.0, pinion_tip_relief_length_mm=2.5,
                               gear_tip_relief_um=8, gear_tip_relief_length_mm=1.0, shape="parabolic")
    assert mod.pinion == FlankRelief(12e-6, 2.5e-3, 0.0, 0.0, "parabolic")
    assert mod.gear == FlankRelief(8e-6, 1e-3, 0.0, 0.0, "parabolic")
    assert profile_modification(PAIR) == ProfileModification()


PATH_MM = (XE - XA) * 1e3
BAD = [
    ("pinion_tip_relief_um", -1.0),
    ("gear_tip_relief_um", math.nan),
    ("gear_root_relief_um", True),
    ("pinion_tip_relief_length_mm", -0.1),
    ("gear_tip_relief_length_mm", PATH_MM * 1.01),
    ("pinion_root_relief_length_mm", "2"),
    ("shape", "cubic"),
    ("tip_relief_um", 3.0),
]


@pytest.mark.parametrize(("name", "value"), BAD)
def test_bad_values_raise_config_error(name, value):
    with pytest.raises(ConfigError) as info:
        profile_modification(PAIR, **{name: value})
    assert info.value.key == f"profile.{name}"
    assert "\n" not in str(info.value)
