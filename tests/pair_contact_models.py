"""The relieved ISO pair of examples/iso_tip_relief.toml, shared by the per-pair contact tests
(test_pair_contact_static.py, test_pair_contact_stability.py, test_pair_contact_checks.py)."""

from hbgear.build import build_model
from hbgear.config import parse_config


def iso_relief_model(torque_Nm=226.0, relief=True, **changes):
    """examples/iso_tip_relief.toml at `torque_Nm` (its relief designed for 226 N m), model fields `changes`."""
    import tomllib
    from pathlib import Path

    data = tomllib.loads((Path(__file__).parents[1] / "examples" / "iso_tip_relief.toml").read_text())
    data["load"]["torque_pinion_Nm"] = torque_Nm
    if not relief:
        data.pop("profile")
    cfg = parse_config(data)
    from hbgear.build import build_tooth_contact

    return build_model(cfg).replace(**changes), build_tooth_contact(cfg)
