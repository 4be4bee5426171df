"""Options of pseudo-arclength continuation: :class:`PseudoArclength` and :func:`sweep_method`."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["PseudoArclength", "sweep_method"]


@dataclass(frozen=True)
class PseudoArclength:
    """Options of pseudo-arclength continuation (all step sizes in scaled units).

    **Arguments:**

    - `ds`: initial arclength step in ``(z, p/p_ref)`` [-]; `ds_min`, `ds_max`: its bounds.
    - `max_corrector_iterations`: Newton iterations allowed per step.
    - `target_iterations`: the Newton-equivalent corrector iterations the step-size control
      aims at (a chord iteration counts one half).
    - `max_angle_deg`: largest angle between successive tangents [deg].
    - `parameter_scale`: ``p_ref`` [units of p]; ``None`` = ``max(|p0|, |p_end|)``.
    - `growth`: largest factor by which ``ds`` grows after a step (it shrinks by at most 2).
    - `max_parameter_step`: largest predicted change of ``p/p_ref`` per step [-] (``None``: no
      limit) -- the resolution in ``p`` where the branch is flat while ``ds_max`` is sized for
      the unknowns.
    - `jit_step`: run each corrector (Newton iterations, line search, tangent) as ONE compiled
      JAX function (``lax.while_loop``) instead of a Python loop, and runs of regular steps (up
      to ``SEGMENT_POINTS`` per call, with the same predictor, acceptance tests and step-size
      control) inside it; any other step (refused, failed, a fold, the end of the range) goes
      back to the Python loop. Needs residual functions that
      JAX can trace in ``(z, p, *args)`` (e.g. :func:`hbgear.engine.hb.residual_functions`,
      the gear pair in ``args``, or :meth:`hbgear.engine.hb.HarmonicBalance.residual_and_jacobians`
      with the system closed over); otherwise the run falls back to the Python corrector with
      a warning. Same algorithm, same points to rounding (LU by XLA instead of scipy); it
      removes the per-evaluation and per-step dispatch and conversion overhead, which dominates
      small and mid-size problems. Costs one compilation per set of residual functions (1-5 s;
      kept in the disk cache, and ``p_ref`` is an argument, so a new range does not recompile).
    - `chord`: with `jit_step`, a modified (chord) Newton corrector: the iterations reuse the LU
      of the bordered Jacobian factored for the tangent at the last converged point (one
      residual evaluation and two triangular solves per iteration, no Jacobian), and the
      Jacobian is evaluated once per point, at the converged point, for its tangent. If the
      chord iteration does not halve ``max |R|`` at every step, the full Newton corrector runs
      from the predictor. Same acceptance test (``max |R| <= tolerance``), so the points agree
      with the Newton corrector's to the tolerance; the iteration counts differ (the step-size
      control counts a chord iteration as half a Newton iteration, by cost, so that the chord
      mode's slower, linear convergence does not shrink the steps). Without `jit_step` it has
      no effect.
    """

    ds: float = 1e-2
    ds_min: float = 1e-7
    ds_max: float = 5e-2
    max_corrector_iterations: int = 10
    target_iterations: int = 4
    max_angle_deg: float = 10.0
    parameter_scale: float | None = None
    growth: float = 2.0
    max_parameter_step: float | None = None
    jit_step: bool = False
    chord: bool = False

    def __post_init__(self):
        if not (0 < self.ds_min <= self.ds <= self.ds_max and math.isfinite(self.ds_max)):
            raise ValueError(f"need 0 < ds_min <= ds <= ds_max < inf, got {self.ds_min}, {self.ds}, {self.ds_max}")
        if not 1 <= self.target_iterations <= self.max_corrector_iterations:
            raise ValueError("need 1 <= target_iterations <= max_corrector_iterations")
        if not 0 < self.max_angle_deg < 90:
            raise ValueError(f"max_angle_deg must be in (0, 90), got {self.max_angle_deg}")
        if self.parameter_scale is not None and not (self.parameter_scale > 0 and math.isfinite(self.parameter_scale)):
            raise ValueError(f"parameter_scale must be a positive finite number, got {self.parameter_scale}")
        if not self.growth > 1:
            raise ValueError("growth must be > 1")
        if self.max_parameter_step is not None and not self.max_parameter_step > 0:
            raise ValueError(f"max_parameter_step must be > 0, got {self.max_parameter_step}")


def sweep_method(p_start, p_stop, step=None) -> PseudoArclength:
    """Continuation options for a sweep of the parameter from `p_start` to `p_stop`.

    ``p_ref`` = the larger end value; the unknowns are scaled (the gear pair: in static
    deflections), so a step moves them by at most 0.25 (``ds_max``) and the parameter by at most
    1/100 of the range (``max_parameter_step``; at least ~100 points on a flat curve); tangents
    turn by at most 5 deg per step. First step: `step` (same unit as ``p``; the gear pair's
    ``[sweep] step_rpm``) or 1/4 of the largest parameter step. Compiled chord corrector.
    """
    scale = max(abs(p_start), abs(p_stop))
    dp_max = abs(p_stop - p_start) / scale / 100
    ds = dp_max / 4 if step is None else step / scale
    dp_max = max(dp_max, ds)
    return PseudoArclength(
        ds=ds, ds_min=min(1e-7, ds / 10), ds_max=max(0.25, ds), max_angle_deg=5.0,
        parameter_scale=scale, max_parameter_step=dp_max, jit_step=True, chord=True,
    )

