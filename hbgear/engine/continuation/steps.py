"""Step geometry and step-size rules shared by the Python loop and the compiled segments:
the unit tangent of the bordered Jacobian, the angle between tangents, the step-size control
after an accepted step and the parameter-step limit (numpy, or JAX with ``xp=jnp``)."""

from __future__ import annotations

import math

import numpy as np
import scipy.linalg


def _grown_step(ds, work, angle_deg, ds_min, ds_max, max_angle_deg, growth, target_iterations, xp=np):
    """``ds`` after an accepted step (:mod:`hbgear.engine.continuation`, item 5): ``ds * clip(min(target / work,
    max_angle / (2 angle)), 1/2, growth)`` kept in ``[ds_min, ds_max]``; numpy or JAX (the
    compiled segments run the same rule)."""
    gain = target_iterations / xp.maximum(work, 1.0)
    gain = xp.where(angle_deg > 0, xp.minimum(gain, max_angle_deg / (2 * xp.maximum(angle_deg, 1e-300))), gain)
    return xp.minimum(ds_max, xp.maximum(ds_min, ds * xp.minimum(growth, xp.maximum(0.5, gain))))


def _limited_step(ds, tangent_p, ds_min, max_parameter_step, xp=np):
    """``ds`` cut so that the predicted change of ``p / p_ref`` is at most `max_parameter_step`
    (``inf``: no limit), not below `ds_min`."""
    slope = xp.abs(tangent_p)
    return xp.where(slope * ds > max_parameter_step,
                    xp.maximum(ds_min, max_parameter_step / xp.maximum(slope, 1e-300)), ds)


def _unit(v):
    """``v / |v|``."""
    return v / np.linalg.norm(v)


def _tangent(bordered, previous):
    """Unit null vector of ``J = bordered[:-1]`` with ``t . previous > 0``; ``bordered`` is the
    ``(m+1, m+1)`` buffer holding ``J``, its last row is overwritten with ``previous``."""
    n = bordered.shape[0] - 1
    bordered[n] = previous
    b = np.zeros(n + 1)
    b[-1] = 1.0
    try:
        t = scipy.linalg.solve(bordered, b, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        t = np.full(n + 1, np.nan)
    if not np.all(np.isfinite(t)):  # degenerate border: fall back to the SVD null vector
        t = np.linalg.svd(bordered[:n])[2][-1]
    t = _unit(t)
    return t if t @ previous >= 0 else -t


def _angle_deg(a, b):
    """Angle between the unit vectors `a` and `b` [deg]."""
    return math.degrees(math.acos(min(1.0, max(-1.0, float(a @ b)))))

