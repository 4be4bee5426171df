"""Friction needs a compressive normal load (MODEL.md section 11): the contact gate of the pair
loads, the sign of the friction power, the linear/nonlinear split and the linear equivalents
along solutions, the energy balance with backlash and friction; the model's own checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "paper_table1.toml"
BACKLASH = ROOT / "examples" / "backlash.toml"


def model_with(*overrides, example=EXAMPLE):
    return build_model(load_config(example, list(overrides)))


def test_model_rejects_lti_with_formulation_b_or_backlash():
    """GearPairModel itself refuses LTI-B and LTI with backlash (ValueError); the config layer
    keeps its ConfigError naming the key."""
    model = model_with("friction.model=LTI")
    with pytest.raises(ValueError, match="formulation 'B'.*LTI"):
        model.replace(formulation="B")
    with pytest.raises(ValueError, match="backlash.*LTI"):
        model.replace(contact="backlash")
    assert model.replace(coupling="LTV", formulation="B").formulation == "B"
    with pytest.raises(ConfigError, match="friction.formulation"):
        model_with("friction.model=LTI", "friction.formulation=B")
    with pytest.raises(ConfigError, match="mesh.backlash_um"):
        model_with("friction.model=LTI", "mesh.backlash_um=40")
