r"""Pseudo-arclength continuation of a solution branch ``R(z; p) = 0`` (any residual).

The branch is followed in the scaled unknowns ``y = (z, p / p_ref)`` so that one arclength step
mixes comparable magnitudes (the harmonic-balance ``z`` are already scaled by the static
deflection; ``p_ref`` defaults to ``max(|p0|, |p_end|)``). Each step:

1. **Tangent** ``t``: the unit null vector of ``[R_z, R_p p_ref]``, from the bordered system
   ``[[R_z, R_p p_ref], [t_prev^T]] t = [0, 1]`` -- which keeps the orientation
   (``t . t_prev > 0``), so the branch is followed through folds.
2. **Predictor** ``y_pred = y + ds t``.
3. **Corrector**: Newton (:func:`hbgear.engine.newton.newton`) on ``R(y) = 0``,
   ``t . (y - y_pred) = 0`` (the hyperplane orthogonal to the tangent), with a backtracking line
   search on ``max |R|``; converged when ``max |R| <= tolerance``.
4. **Acceptance**: the corrector converged within ``max_corrector_iterations``, moved less than
   ``ds`` off the predictor, and the new tangent turned by at most ``max_angle_deg``; otherwise
   ``ds`` is halved and the step retried. Below ``ds_min`` the run stops with
   :attr:`Status.STEP_TOO_SMALL` and a message saying where, what was tried and the residual.
5. **Step size**: ``ds *= clip(min(target_iterations / work, max_angle / (2 angle)), 1/2, 2)``, with
   ``work`` the corrector's Newton iterations plus half its chord iterations (a chord iteration
   is one residual and two triangular solves, about half a Newton iteration's cost),
   kept in ``[ds_min, ds_max]`` and, optionally, so that the predicted change of ``p/p_ref`` is
   at most ``max_parameter_step``.

A **fold** (turning point in ``p``) is where the ``p``-component of the tangent changes sign; it
is located by Illinois regula falsi on that component along the arc and inserted into the
branch as a converged point of kind :attr:`PointKind.FOLD`. The run stops exactly at ``p_end``
(the last point is solved at ``p = p_end``), at ``max_points``, or when the branch turns back
past ``p0``. Only converged points are ever stored: no silent gaps.

**Modules**, one job each:

- :mod:`.options`: :class:`PseudoArclength` (the options above) and :func:`sweep_method`;
- :mod:`.branch`: the result, :class:`Branch`, its :class:`Status` and :data:`MESSAGES`, and
  :class:`PointKind`;
- :mod:`.steps`: the tangent (item 1), the angle between tangents, the step-size rules (item 5);
- :mod:`.corrector`: the Python corrector (item 3) and its outcomes, ``_Point`` / ``_Failure``;
- :mod:`.compiled`: the same corrector compiled, and runs of regular steps in one call
  (``jit_step``, ``chord``);
- :mod:`.folds`: fold location, and the Illinois regula falsi it uses;
- :mod:`.progress`: the progress bar;
- :mod:`.driver`: :func:`continuation`, the loop: start, steps, acceptance (item 4), folds,
  landing on ``p_end``, stops.
"""

# the internals below are re-exported for the tests and the benchmarks (not public API)
from .branch import MESSAGES, Branch, PointKind, Status  # noqa: F401
from .compiled import _JIT_CACHE, SEGMENT_POINTS, _Compiled, _jit_corrector  # noqa: F401
from .corrector import CHORD_ITERATION_WORK, _python_corrector  # noqa: F401
from .driver import continuation, solve_at_parameter
from .folds import IllinoisBracket  # noqa: F401
from .options import PseudoArclength, sweep_method

__all__ = ["PseudoArclength", "continuation", "solve_at_parameter", "sweep_method", "Branch", "Status", "PointKind"]
