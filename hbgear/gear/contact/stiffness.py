r"""Single tooth-pair stiffness along the path of contact (MODEL.md section 9).

A pair stiffness model is a small frozen object with one method,
``stiffness(xi, xp) -> k_pair(xi)`` [N/m], where ``xi`` is the position along the line of
action measured from the start of active contact (``0 <= xi <= x_E - x_A``). It evaluates on
numpy and jax.numpy arrays alike (``xp``), with no Python branching on array values, so it can
sit inside a JAX-traced residual.

This module holds the constant model and the user table (with its loader), and the paper's
mesh-level rectangular ``k(s)`` for the static TE of configs that keep it; the ISO 6336-1 model is
in :mod:`hbgear.gear.contact.iso6336`.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import ConfigError
from ..geometry import GearPair

__all__ = [
    "ConstantPairStiffness",
    "RectangularMeshStiffness",
    "TABLE_COVERAGE_TOLERANCE",
    "TablePairStiffness",
    "load_pair_stiffness_table",
]

#: A table must reach both ends of the path of contact to within this fraction of its length.
TABLE_COVERAGE_TOLERANCE = 0.005

_KEY = "mesh.pair_stiffness_file"
_STIFFNESS = "stiffness_MN_per_m"
_POSITIONS = ("position_mm", "roll_angle_deg")
_ALLOWED = (
    "a readable CSV file with a header row of exactly two columns, position_mm (or roll_angle_deg) "
    "and stiffness_MN_per_m"
)


@dataclass(frozen=True)
class ConstantPairStiffness:
    """``k_pair(xi) = k_1`` everywhere on the path.

    **Arguments:** `stiffness_N_per_m`: ``k_1`` [N/m]. With no profile modification this is the
    paper's rectangular model with ``k_max = 2 k_1``, ``k_min = k_1``.
    """

    stiffness_N_per_m: float

    def stiffness(self, xi, xp=np):
        """``k_pair(xi)`` [N/m], the shape of `xi`."""
        return self.stiffness_N_per_m + 0.0 * xp.asarray(xi)


@dataclass(frozen=True)
class RectangularMeshStiffness:
    """The paper's mesh-level ``k(s)``: ``k_max`` while two pairs are in contact, ``k_min`` while
    one, shared equally among the pairs in contact.

    With ``k_max != 2 k_min`` this is not a single-pair stiffness (a pair's share depends on how
    many pairs are in contact, not on its position alone), so it gives every slot's stiffness
    from the contact pattern: ``k_j = k(s) / n(s)`` on the ``n(s)`` pairs in contact. The loaded
    static TE is then ``eps + N/k(s)`` (the dynamic model's quasi-static state).

    **Arguments:** `k_max_N_per_m`, `k_min_N_per_m` [N/m] (contact ratios in (1, 2)).
    """

    k_max_N_per_m: float
    k_min_N_per_m: float

    def slot_stiffness(self, in_contact, xp=np):
        """``k_j`` [N/m] of every slot, the shape of `in_contact` (``(slots,) + shape``, bool)."""
        in_contact = xp.asarray(in_contact)
        count = xp.sum(in_contact, axis=0)
        mesh = xp.where(count >= 2, self.k_max_N_per_m, self.k_min_N_per_m)
        return xp.where(in_contact, mesh / xp.maximum(count, 1), 0.0)

    @property
    def pair_max_N_per_m(self) -> float:
        """The largest share a pair carries: ``max(k_max/2, k_min)`` [N/m]."""
        return max(self.k_max_N_per_m / 2, self.k_min_N_per_m)


@dataclass(frozen=True)
class TablePairStiffness:
    """Piecewise-linear interpolation of a table ``(xi_i, k_i)``.

    ``k_pair(xi) = k_i + (k_{i+1} - k_i) (xi - xi_i) / (xi_{i+1} - xi_i)`` on
    ``[xi_i, xi_{i+1}]``, held at the end values outside the table. Linear interpolation is
    monotone between samples and never overshoots them, so a positive table gives a positive
    stiffness everywhere.

    **Arguments:** `positions_m`: strictly increasing ``xi_i`` [m] from the start of active
    contact; `stiffness_N_per_m`: ``k_i > 0`` [N/m]. Build it with
    :func:`load_pair_stiffness_table` to have both checked.
    """

    positions_m: tuple[float, ...]
    stiffness_N_per_m: tuple[float, ...]

    def stiffness(self, xi, xp=np):
        """``k_pair(xi)`` [N/m], the shape of `xi`."""
        return xp.interp(xp.asarray(xi), xp.asarray(self.positions_m), xp.asarray(self.stiffness_N_per_m))


def _bad(path: Path, detail: str, allowed: str = _ALLOWED, key: str = _KEY) -> ConfigError:
    return ConfigError(key, f"{path}: {detail}", allowed)


def _read_rows(path: Path, key: str) -> tuple[str, bool, list[tuple[int, list[str]]]]:
    """The position column's name, whether it comes first, and the numbered data rows (blank
    lines skipped)."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            rows = [(number, row) for number, row in enumerate(csv.reader(handle), start=1)
                    if any(cell.strip() for cell in row)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise _bad(path, f"cannot be read ({type(exc).__name__})", key=key) from None
    if not rows:
        raise _bad(path, "empty file", key=key)
    header = [cell.strip() for cell in rows[0][1]]
    if len(header) == 2 and header[1] == _STIFFNESS and header[0] in _POSITIONS:
        return header[0], True, rows[1:]
    if len(header) == 2 and header[0] == _STIFFNESS and header[1] in _POSITIONS:
        return header[1], False, rows[1:]
    raise _bad(path, f"header {','.join(header)!r}", key=key)


def load_pair_stiffness_table(path, pair: GearPair, key: str = _KEY) -> TablePairStiffness:
    """Read and check a single-pair stiffness table for `pair`.

    Columns (header row, either order): ``position_mm`` along the line of action from the start
    of active contact, or ``roll_angle_deg``, the pinion roll angle ``zeta`` (the involute
    roll angle from the base-circle tangency ``T_1``), converted with
    ``xi = R_bp (zeta - zeta_A)``, ``zeta_A = x_A / R_bp``; and ``stiffness_MN_per_m``.

    Checks, each a :class:`~hbgear.errors.ConfigError` naming `key`, the file and the offending
    row: the file is readable; exactly those two columns; every cell a finite number; at least
    two rows; strictly increasing positions; stiffness > 0; and the table covers the path of
    contact ``[0, x_E - x_A]`` to within :data:`TABLE_COVERAGE_TOLERANCE` of its length.

    **Arguments:** `path`: the CSV file; `pair`: the geometry the table belongs to; `key`: the
    config key named in errors.

    **Returns:** a :class:`TablePairStiffness` in SI units.
    """
    path = Path(path)
    position_name, position_first, rows = _read_rows(path, key)
    positions, values = [], []
    for number, row in rows:
        cells = [cell.strip() for cell in row]
        if len(cells) != 2:
            raise _bad(path, f"line {number} has {len(cells)} fields", "two numbers per row", key)
        try:
            numbers = [float(cell) for cell in cells]
        except ValueError:
            raise _bad(path, f"line {number} {','.join(cells)!r}", "finite numbers", key) from None
        if not all(math.isfinite(x) for x in numbers):
            raise _bad(path, f"line {number} {','.join(cells)!r}", "finite numbers", key)
        position, stiffness = numbers if position_first else numbers[::-1]
        if stiffness <= 0.0:
            raise _bad(path, f"line {number} {_STIFFNESS} = {stiffness!r}", f"{_STIFFNESS} > 0", key)
        if positions and position <= positions[-1]:
            raise _bad(path, f"line {number} {position_name} = {position!r}", f"strictly increasing {position_name}",
                       key)
        positions.append(position)
        values.append(stiffness)
    if len(positions) < 2:
        raise _bad(path, f"{len(positions)} data row(s)", "at least 2 data rows", key)
    if position_name == "position_mm":
        xi = np.asarray(positions) * 1e-3
    else:
        xi = pair.base_radius_pinion_m * np.radians(positions) - pair.contact_start_m
    path_length = pair.contact_end_m - pair.contact_start_m
    tolerance = TABLE_COVERAGE_TOLERANCE * path_length
    if xi[0] > tolerance or xi[-1] < path_length - tolerance:
        raise _bad(
            path,
            f"covers {xi[0] * 1e3:.4f} .. {xi[-1] * 1e3:.4f} mm",
            f"a table covering the path of contact 0 .. {path_length * 1e3:.4f} mm "
            f"(to within {TABLE_COVERAGE_TOLERANCE:.1%} of its length)",
            key,
        )
    return TablePairStiffness(tuple(float(x) for x in xi), tuple(float(k) * 1e6 for k in values))
