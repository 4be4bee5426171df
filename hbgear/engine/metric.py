r"""The metric of continuation in harmonic-balance unknowns: the means of soft coordinates
counted in their own sizes.

A system may declare (:meth:`~hbgear.engine.system.PeriodicSystem.arclength_mean_scales`) that a
coordinate's mean moves far more per unit of response than the rest (a soft spring standing for
a free rotation); continued in plain unknowns it alone fills the arclength and the steps crawl in
the parameter. Continuation then works in ``y = z / sizes``: :func:`arclength_sizes` gives the
sizes, :func:`sized_functions_of` the residual functions in ``y`` (``R(sizes y)``, Jacobian
``R_z diag(sizes)``), :func:`continuation_functions` whichever applies. Only the metric changes,
not the solutions. Used by every continuation of the engine: the ``nu`` curve
(:mod:`hbgear.engine.response`) and the ``nu = 2`` branches (:mod:`hbgear.engine.bifurcation`).
"""

from __future__ import annotations

from functools import lru_cache

import jax.numpy as jnp
import numpy as np

from .hb import HarmonicBalance, _functions_of, jacobian_is_structured, residual_functions

__all__ = ["arclength_sizes", "sized_functions_of", "continuation_functions"]


def arclength_sizes(hb: HarmonicBalance, system, p) -> np.ndarray | None:
    """The system's :meth:`~hbgear.engine.system.PeriodicSystem.arclength_mean_scales` at `p` as
    sizes of the unknowns of `hb` ``(size,)`` (the means' slots; 1 elsewhere), or ``None`` when
    it declares none or all are 1."""
    declared = getattr(system, "arclength_mean_scales", None)  # duck-typed systems may lack it
    scales = None if declared is None else declared(p)
    if scales is None:
        return None
    scales = np.asarray(scales, dtype=float).reshape(hb.ndof)
    if not np.all(np.isfinite(scales) & (scales > 0)):
        raise ValueError(f"{type(system).__name__}.arclength_mean_scales: positive finite numbers, got {scales}")
    if np.all(scales == 1.0):
        return None
    sizes = np.ones(hb.size)
    sizes[np.arange(hb.ndof) * hb.block] = scales
    return sizes


@lru_cache(maxsize=16)
def sized_functions_of(hb: HarmonicBalance):
    """:func:`~hbgear.engine.hb.residual_functions` in the unknowns ``y = z / sizes`` (`sizes`
    the last extra argument): ``R(sizes y)`` and its Jacobian ``R_z diag(sizes)``."""
    plain, _ = _functions_of(hb)

    def residual_and_jacobians(y, p, system, prepared, sizes):
        res, jz, jp = plain(jnp.asarray(y) * sizes, p, system, prepared)
        if jacobian_is_structured(prepared):  # a PortJacobian or a KrylovJacobian: its scaled form
            return res, jz.scaled(jnp.asarray(sizes)), jp
        return res, jz * sizes[None, :], jp

    def residual(y, p, system, prepared, sizes):
        return hb.residual(jnp.asarray(y) * sizes, p, system, prepared)

    residual_and_jacobians.jacobian_is_structured = lambda system, prepared, sizes: jacobian_is_structured(prepared)
    # all they close over is `hb` (frozen settings): programs traced from them may be kept on disk
    residual_and_jacobians.program_key = residual.program_key = ("engine.metric.sized_functions_of", hb)
    return residual_and_jacobians, residual


def continuation_functions(hb: HarmonicBalance, system, p):
    """``(residual_and_jacobians, residual, args, sizes)`` that a continuation in `p` follows: the
    residual functions of `hb`, or with :func:`arclength_sizes` at `p` those in the unknowns
    ``y = z / sizes`` (`sizes` the last argument; ``None`` when there are none)."""
    rj, r, fixed = residual_functions(hb, system)
    sizes = arclength_sizes(hb, system, p)
    if sizes is not None:  # the continuation's unknowns z / sizes, its residual R(sizes y)
        rj, r = sized_functions_of(hb)
        fixed = (*fixed, sizes)
    return rj, r, fixed, sizes
