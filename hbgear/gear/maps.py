"""Stability maps of the gear pair over speed x contact ratio (MODEL.md section 6, paper Fig. 13).

Functions of models (one per contact ratio, ``k_max``/``k_min`` held: see
:func:`hbgear.build.model_at_contact_ratio`); :func:`hbgear.stability_map` takes a config.
"""

from __future__ import annotations

import numpy as np

from ..engine.floquet import hill_multipliers_batch, max_abs_multiplier
from ..errors import ConvergenceError
from .monodromy import _is_piecewise_constant, multipliers_linear
from .solve import rpm_to_rad_s, solve_periodic
from .system import GearSystem

__all__ = ["stability_map", "stability_map_ltv_a", "stability_row"]


def stability_map_ltv_a(models, speeds_rpm) -> np.ndarray:
    """``max |multiplier|`` per mesh period over models x speeds for LTV formulation A, exactly.

    **Arguments:** `models`: a sequence of LTV-A (or LTI) models (e.g. one per contact ratio);
    `speeds_rpm`: 1-D pinion speeds [rpm].

    **Returns:** array ``(len(models), len(speeds_rpm))`` (the trivial pair of the reaction
    boundary excluded). All matrix exponentials of one model (segments x speeds) are one batched
    Pade evaluation: a 100 x 50 map takes well under a second.

    **Raises:** `ValueError` if a model is not LTV-A/LTI (use :func:`stability_map`).
    """
    omegas = rpm_to_rad_s(np.asarray(speeds_rpm, dtype=float))
    out = np.empty((len(models), omegas.size))
    for i, model in enumerate(models):
        if not _is_piecewise_constant(model):
            raise ValueError("stability_map_ltv_a needs LTV formulation-A (or LTI) models; use stability_map")
        out[i] = np.max(np.abs(multipliers_linear(model, omegas, substeps=1)), axis=-1)
    return out


def stability_row(model, speeds_rpm, *, harmonics: int = 24, nu: int = 1, samples: int | None = None) -> np.ndarray:
    """``max |multiplier|`` per mesh period at each speed of one model: batched exact monodromy for
    a linear model, else harmonic balance (each speed started from the last) + Hill's method
    batched over the row (``nan`` where harmonic balance does not converge).

    The unit of work of ``hbgear stability-map`` (one task per contact ratio when distributed).
    """
    omegas = rpm_to_rad_s(np.asarray(speeds_rpm, dtype=float))
    if model.is_linear:
        return np.max(np.abs(multipliers_linear(model, omegas)), axis=-1)
    out = np.full(omegas.size, np.nan)
    z, solved, zs, hb = None, [], [], None
    for k, omega in enumerate(omegas):
        try:
            sol = solve_periodic(model, float(omega), harmonics=harmonics, nu=nu, samples=samples, z0=z)
        except ConvergenceError:
            z = None
            continue
        z = sol.z
        solved.append(k)
        zs.append(np.asarray(sol.z))
        hb = sol.hb
    if solved:  # one batched Hill call for the row (all points share hb: same H, nu, N)
        mults = hill_multipliers_batch(hb, np.stack(zs), omegas[solved], GearSystem(model))
        out[solved] = [max_abs_multiplier(m) ** (1.0 / hb.nu) for m in mults]  # per mesh period
    return out


def stability_map(models, speeds_rpm, *, harmonics: int = 24, nu: int = 1, samples: int | None = None) -> np.ndarray:
    """``max |multiplier|`` over models x speeds for any model (:func:`stability_row` per model).

    **Returns:** array ``(len(models), len(speeds_rpm))``.
    """
    return np.stack([stability_row(m, speeds_rpm, harmonics=harmonics, nu=nu, samples=samples) for m in models])
