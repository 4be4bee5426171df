"""Stability maps of the gear pair over speed x contact ratio (MODEL.md section 6, paper Fig. 13)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..engine.floquet import hill_multipliers_batch, max_abs_multiplier
from .monodromy import _is_piecewise_constant, multipliers_linear

__all__ = ["model_at_contact_ratio", "stability_map", "stability_map_ltv_a", "stability_row"]


# ============================================================================ maps


def model_at_contact_ratio(cfg, contact_ratio: float):
    """``build_model(cfg, contact_ratio=...)``: ``k_max``, ``k_min`` held, ``k_mean`` follows (MODEL.md section 2)."""
    from ..build import build_model

    return build_model(cfg, contact_ratio=float(contact_ratio))


def _models(cfg_or_models, contact_ratios):
    if isinstance(cfg_or_models, Sequence) and not isinstance(cfg_or_models, str):
        return list(cfg_or_models), [float(m.contact_ratio) for m in cfg_or_models]
    from ..build import build_model

    if contact_ratios is None:
        return [build_model(cfg_or_models)], None
    return [model_at_contact_ratio(cfg_or_models, g) for g in contact_ratios], list(contact_ratios)


def stability_map_ltv_a(cfg_or_models, speeds_rpm, contact_ratios=None) -> np.ndarray:
    """``max |multiplier|`` over speed x contact ratio for LTV formulation A, exactly and fast.

    **Arguments:** `cfg_or_models`: a ``RunConfig`` (one model per contact ratio is built with
    :func:`model_at_contact_ratio`, ``k_max``/``k_min`` held) or a sequence of models;
    `speeds_rpm`: 1-D pinion speeds [rpm]; `contact_ratios`: 1-D (with a config).

    **Returns:** array ``(len(contact_ratios), len(speeds_rpm))`` of the largest multiplier
    modulus per mesh period (trivial rigid-body pair of the reaction boundary excluded).

    All matrix exponentials of one contact ratio (segments x speeds) are one batched Pade
    evaluation (:func:`expm_batched`); a 100 x 50 map takes well under a second.

    **Raises:** `ValueError` if a model is not LTV-A/LTI (use :func:`stability_map`).
    """
    models, _ = _models(cfg_or_models, contact_ratios)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    out = np.empty((len(models), omegas.size))
    for i, model in enumerate(models):
        if not _is_piecewise_constant(model):
            raise ValueError("stability_map_ltv_a needs LTV formulation-A (or LTI) models; use stability_map")
        out[i] = np.max(np.abs(multipliers_linear(model, omegas, substeps=1)), axis=-1)
    return out


@dataclass(frozen=True)
class _HBSettings:
    harmonics: int = 24
    nu: int = 1
    samples: int | None = None


def _row_for_model(model, omegas: np.ndarray, settings: _HBSettings):
    """max |multiplier| at each speed for one model: batched monodromy if linear, else HB + Hill."""
    if model.is_linear:
        return np.max(np.abs(multipliers_linear(model, omegas)), axis=-1)
    from ..engine.hb import HarmonicBalance
    from ..errors import ConvergenceError
    from .solve import solve_periodic
    from .system import GearSystem

    out = np.full(omegas.size, np.nan)
    z = None
    solved, zs = [], []
    for k, omega in enumerate(omegas):
        try:
            sol = solve_periodic(
                model, float(omega), harmonics=settings.harmonics, nu=settings.nu, samples=settings.samples, z0=z
            )
        except ConvergenceError:
            z = None
            continue
        z = sol.z
        solved.append(k)
        zs.append(np.asarray(sol.z))
        hb = HarmonicBalance(model.ndof, sol.harmonics, sol.nu, sol.samples)
    if solved:
        # one batched Hill call for the row (all points share hb: same H, nu, N)
        mults = hill_multipliers_batch(hb, np.stack(zs), omegas[solved], GearSystem(model))
        # per mesh period, comparable with the linear maps
        out[solved] = [max_abs_multiplier(m) ** (1.0 / hb.nu) for m in mults]
    return out


def _settings(cfg) -> _HBSettings:
    solver = getattr(cfg, "solver", None)
    if solver is None:
        return _HBSettings()
    harmonics = solver.harmonics if solver.harmonics is not None else 24
    return _HBSettings(harmonics=int(harmonics), nu=int(solver.subharmonic), samples=int(solver.time_samples))


def stability_row(cfg, contact_ratio: float, speeds_rpm) -> np.ndarray:
    """One row of the map: ``max |multiplier|`` over `speeds_rpm` at one contact ratio.

    The unit of work of ``hbgear stability-map`` (one task per contact ratio when distributed).
    Linear models use the batched exact monodromy; others harmonic balance + Hill (``nan``
    where harmonic balance does not converge).
    """
    model = model_at_contact_ratio(cfg, contact_ratio)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    return _row_for_model(model, omegas, _settings(cfg))


def stability_map(cfg_or_models, speeds_rpm, contact_ratios=None) -> np.ndarray:
    """``max |multiplier|`` over contact ratio x speed for any model (see :func:`stability_row`).

    **Returns:** array ``(len(contact_ratios), len(speeds_rpm))``.
    """
    models, _ = _models(cfg_or_models, contact_ratios)
    omegas = np.asarray(speeds_rpm, dtype=float) * (2.0 * np.pi / 60.0)
    settings = _settings(cfg_or_models) if not isinstance(cfg_or_models, Sequence) else _HBSettings()
    return np.stack([_row_for_model(m, omegas, settings) for m in models])
