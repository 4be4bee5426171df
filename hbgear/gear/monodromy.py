r"""Floquet multipliers of the gear pair's periodic steady states (MODEL.md section 6).

The gear-pair forms of :mod:`hbgear.engine.monodromy` (models and pinion speeds instead of
systems and parameters; multipliers per mesh period):

- **Exact monodromy for linear models** (:func:`monodromy_linear`, :func:`monodromy_ltv_a`).
  For LTV formulation A (and LTI) the coefficients are piecewise constant in the mesh phase
  (``k(t)`` is a rectangular pulse, friction is an excitation), so the monodromy matrix over
  one mesh period is the exact product of matrix exponentials of the paper's Eq. 20. For
  LTV formulation B the coefficients are piecewise smooth (``xi_j(t)`` is linear in ``t``);
  fourth-order Magnus steps between the breakpoints are used. Both are batched over speeds.
- **Variational equations** (:func:`monodromy_variational`) along any periodic solution
  (formulation B, NLTV, backlash).

Limitation: with the Coulomb law (``sgn``) the linearisation ignores the jumps of ``mu`` at
the instantaneous pitch-point crossings of NLTV models (no saltation matrices); smooth laws
(arctan) are treated exactly.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..engine import monodromy as _engine
from ..engine.floquet import hill_multipliers
from ..engine.monodromy import expm_batched
from .system import GearSystem

__all__ = [
    "expm_batched",
    "floquet_multipliers",
    "monodromy_linear",
    "monodromy_ltv_a",
    "monodromy_variational",
    "multipliers_linear",
]


def _is_piecewise_constant(model) -> bool:
    """LTI, or LTV formulation A, without backlash: coefficients constant between breakpoints."""
    return GearSystem(model).piecewise_constant_coefficients


def monodromy_linear(model, omegas, *, substeps: int | None = None, balanced: bool = False) -> np.ndarray:
    """Monodromy matrices over one mesh period of a linear model, batched over speeds.

    **Arguments:** `model`: a :class:`~hbgear.gear.model.GearPairModel` with ``model.is_linear``
    (LTI, or LTV with teeth that never separate); `omegas`: pinion speeds [rad/s], scalar or
    1-D; `substeps`: Magnus sub-steps per segment (default 1 for LTI / LTV-A, exact; for LTV-B
    doubled from 16 until converged, :func:`hbgear.engine.monodromy.monodromy_linear`); `balanced`: the matrix for ``(q, q'/w_n)``, ``w_n =
    sqrt(k_mean/m_e)`` (same eigenvalues, better conditioned).

    **Returns:** ``Phi`` with ``x(Tm) = Phi x(0)``, ``x = (q, q')`` in SI; shape
    ``(len(omegas), 2n, 2n)`` (``(2n, 2n)`` for a scalar speed).

    **Raises:** `ValueError` for a non-linear model (use :func:`monodromy_variational`).
    """
    if not model.is_linear:
        raise ValueError(
            f"monodromy_linear needs a linear model (LTI/LTV without backlash), got coupling="
            f"{model.coupling!r}, contact={model.contact!r}; use monodromy_variational or Hill"
        )
    return _engine.monodromy_linear(GearSystem(model), omegas, substeps=substeps, balanced=balanced)


def monodromy_ltv_a(model, omega) -> np.ndarray:
    """Exact monodromy matrix over one mesh period for LTV formulation A (paper Eq. 20).

    ``Phi = prod_j exp(A_j (s_{j+1} - s_j) Tm)`` over the segments between the breakpoints
    (pair entry, pair exit, pitch crossing), ``A_j`` the constant state matrix of segment ``j``.
    `omega` [rad/s] scalar -> ``(2n, 2n)``; 1-D -> ``(len, 2n, 2n)``.

    **Raises:** `ValueError` unless the model is LTV (or LTI), formulation A, without backlash.
    """
    if not _is_piecewise_constant(model):
        raise ValueError(
            "monodromy_ltv_a needs an LTV formulation-A (or LTI) model without backlash, got "
            f"coupling={model.coupling!r}, formulation={model.formulation!r}, contact={model.contact!r}"
        )
    return monodromy_linear(model, omega, substeps=1)


def multipliers_linear(model, omegas, *, substeps: int | None = None, drop_trivial: bool = True) -> np.ndarray:
    """Floquet multipliers (per mesh period) of a linear model; shape ``(len(omegas), 2n')``,
    ``2n' = 2n`` less the trivial pair of the reaction boundary when `drop_trivial`."""
    if not model.is_linear:
        raise ValueError(f"multipliers_linear needs a linear model, got coupling={model.coupling!r}, "
                         f"contact={model.contact!r}")
    return _engine.multipliers_linear(GearSystem(model), omegas, substeps=substeps, drop=drop_trivial)


def monodromy_variational(model, solution_or_state_fn: Any, omega: float, nu: int = 1, *, rtol: float = 1e-10,
                          atol: float = 1e-12) -> np.ndarray:
    """Monodromy matrix over one base period ``nu Tm`` from the variational equations
    (:func:`hbgear.engine.monodromy.monodromy_variational`).

    **Arguments:** `model`: any :class:`~hbgear.gear.model.GearPairModel`;
    `solution_or_state_fn`: a :class:`~hbgear.gear.solve.PeriodicSolution` (its ``nu``
    overrides `nu`) or a callable ``base_fraction -> (q, q')`` with arrays of shape ``(ndof,)``
    or ``(ndof, 1)`` [m, m/s]; `omega`: pinion speed [rad/s]; `nu`: base period in mesh periods.

    **Returns:** ``Phi``, shape ``(2n, 2n)``, ``x(nu Tm) = Phi x(0)``.
    """
    n = model.ndof
    if hasattr(solution_or_state_fn, "state_at"):
        solution = solution_or_state_fn
        nu = int(solution.nu)
        state = _engine.state_synthesis(solution.coefficients, solution.harmonics, solution.base_frequency)
    else:
        state_fn = solution_or_state_fn

        def state(tau):
            q, qd = state_fn(np.array([tau]))
            return np.asarray(q, float).reshape(n), np.asarray(qd, float).reshape(n)

    return _engine.monodromy_variational(GearSystem(model), float(omega), state, nu, rtol=rtol, atol=atol)


def floquet_multipliers(model, omega: float, *, solution=None, harmonics: int = 24, nu: int = 1,
                        samples: int | None = None, method: str = "auto") -> np.ndarray:
    """Floquet multipliers of the steady state at `omega` [rad/s].

    `method`: ``"auto"`` (exact monodromy for linear models, else Hill), ``"monodromy"``,
    ``"hill"`` or ``"variational"``. For non-linear models a
    :class:`~hbgear.gear.solve.PeriodicSolution` may be given, else one is solved for.
    Multipliers from Hill and the variational equations are over the base period ``nu Tm``.
    """
    if method == "auto":
        method = "monodromy" if model.is_linear else "hill"
    if method == "monodromy":
        return multipliers_linear(model, float(omega))
    from ..engine.hb import HarmonicBalance
    from .solve import solve_periodic

    if solution is None:
        solution = solve_periodic(model, omega, harmonics=harmonics, nu=nu, samples=samples)
    if method == "variational":
        phi = monodromy_variational(model, solution, omega)
        return _engine.drop_trivial(np.linalg.eigvals(phi), GearSystem(model))
    if method != "hill":
        raise ValueError(f"method must be 'auto', 'monodromy', 'hill' or 'variational', got {method!r}")
    hb = HarmonicBalance(model.ndof, solution.harmonics, solution.nu, solution.samples)
    return hill_multipliers(hb, solution.z, float(omega), GearSystem(model))
