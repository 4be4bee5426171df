"""Realistic tooth contact for the gear pair (MODEL.md section 9).

Single-pair stiffness along the path of contact (constant, user table, ISO 6336-1 method B,
potential energy),
profile modifications along the line of action, and the loaded static transmission error with
its load sharing and the Harris map. Pure functions and small frozen classes; evaluated on
numpy or jax.numpy arrays where they can sit inside a traced residual.
"""

from .iso6336 import Iso6336PairStiffness as Iso6336PairStiffness
from .iso6336 import Iso6336Stiffness as Iso6336Stiffness
from .iso6336 import iso6336_stiffness as iso6336_stiffness
from .potential_energy import potential_energy_pair_stiffness as potential_energy_pair_stiffness
from .potential_energy import tooth_compliances as tooth_compliances
from .profile import FlankRelief as FlankRelief
from .profile import ProfileModification as ProfileModification
from .profile import profile_modification as profile_modification
from .static_te import LoadedTE as LoadedTE
from .static_te import StaticTE as StaticTE
from .static_te import harris_map as harris_map
from .static_te import loaded_te_table as loaded_te_table
from .static_te import pair_positions as pair_positions
from .static_te import pair_stiffness_max as pair_stiffness_max
from .static_te import slot_stiffness as slot_stiffness
from .static_te import solve_static_contact as solve_static_contact
from .static_te import static_transmission_error as static_transmission_error
from .static_te import unloaded_ste as unloaded_ste
from .stiffness import ConstantPairStiffness as ConstantPairStiffness
from .stiffness import RectangularMeshStiffness as RectangularMeshStiffness
from .stiffness import TablePairStiffness as TablePairStiffness
from .stiffness import load_pair_stiffness_table as load_pair_stiffness_table

__all__ = [
    "ConstantPairStiffness",
    "FlankRelief",
    "Iso6336PairStiffness",
    "Iso6336Stiffness",
    "LoadedTE",
    "ProfileModification",
    "RectangularMeshStiffness",
    "StaticTE",
    "TablePairStiffness",
    "harris_map",
    "iso6336_stiffness",
    "load_pair_stiffness_table",
    "loaded_te_table",
    "pair_positions",
    "pair_stiffness_max",
    "potential_energy_pair_stiffness",
    "profile_modification",
    "slot_stiffness",
    "solve_static_contact",
    "static_transmission_error",
    "tooth_compliances",
    "unloaded_ste",
]
