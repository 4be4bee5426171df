r"""The contract between a periodic system and the harmonic-balance engine.

A system is the second-order equation

.. math::  M(p)\, q'' = Q(s, q, q'; p), \qquad Q = Q_{lin} + Q_{nl},

where ``q`` holds ``ndof`` coordinates, ``p`` is the scalar parameter a study varies (a speed, a
forcing frequency, a torque, ...), and ``s = frac(w_exc(p) t / 2 pi)`` in [0, 1) is the phase of
the explicit time dependence, whose period is ``2 pi / w_exc(p)``. ``Q_lin`` is affine in
``(q, q')`` with ``s``-periodic coefficients; harmonic balance turns it into exact convolution
matrices (its Fourier coefficients by quadrature between the breakpoints). ``Q_nl`` is the rest;
it is evaluated by alternating frequency-time (AFT) on uniform samples, its jumps at the
breakpoints corrected exactly.

Write a system by subclassing :class:`PeriodicSystem` as a frozen dataclass registered as a JAX
pytree, so that its float fields are traced arguments of the compiled programs (a new parameter
value never recompiles)::

    @jax.tree_util.register_dataclass
    @dataclasses.dataclass(frozen=True)
    class Oscillator(hbgear.PeriodicSystem):
        damping: float = 0.02
        ndof = 1                                   # a class attribute: structure, not data
        is_linear = False
        def mass_matrix(self, p, xp=np): return xp.ones((1, 1))
        def excitation_frequency(self, p): return p
        def force(self, s, q, qd, p, part, extra, xp=np): ...

A subclass must implement (the engine calls nothing else):

1. ``ndof`` -- the number of coordinates (an ``int``, a class attribute or property).
2. ``is_linear`` -- ``True`` iff ``Q_nl`` is identically zero (then one linear solve is exact).
3. ``mass_matrix(p, xp)`` -- ``M``, shape ``(ndof, ndof)``, symmetric positive definite.
4. ``excitation_frequency(p)`` -- ``w_exc`` [rad/s] (the fundamental of the time dependence;
   the harmonic-balance base frequency is ``w_exc / nu``).
5. ``force(s, q, qd, p, part, extra, xp)`` -- ``Q`` at the phases ``s`` (any shape), with ``q``,
   ``qd`` of shape ``(ndof,) + s.shape``; returns ``(ndof,) + s.shape``. ``part`` is
   ``"linear"`` (``Q_lin`` only: it must be exactly affine in ``q``, ``qd``, the engine probes
   it at unit vectors), ``"nonlinear"`` (``Q_nl``) or ``"all"``. ``extra`` is the constant force
   unknown of a free coordinate (see ``free_mean_dof``; ``0.0`` otherwise). ``xp`` is ``numpy``
   or ``jax.numpy``: write the force with ``xp`` functions only and no Python branching on
   array values, so that the same code serves numpy (time integration, probes) and JAX
   (residuals, exact Jacobians by automatic differentiation).

Declared facts (class attributes with the defaults below; a claim the engine can check is
checked, e.g. ``forcing_affine_in_frequency`` at a third parameter value, ``ndof`` against the
shapes returned, ``is_linear`` at a probe state):

- ``breakpoints(p, xp)`` -- phases in [0, 1] where ``Q`` may jump (default: none); values outside
  [0, 1] and duplicates are ignored, so a traced computation may return candidates unfiltered.
- ``derivative_forcing(s, p, xp)`` -- ``None`` (default) or ``G(s; p)``, shape
  ``(ndof,) + s.shape``, smooth between the breakpoints and free to jump at them: ``Q_lin``
  then holds, besides what ``force`` returns, the time derivative ``dG/dt`` taken in the sense of
  distributions, so a jump ``[G]`` at ``t_c`` is the impulse ``[G] delta(t - t_c)``. ``force``
  must contain no part of ``dG/dt`` (not even its pointwise part). The engine takes the Fourier
  coefficients ``G_m`` by the quadrature between the breakpoints and adds ``i m w G_m`` to the
  forcing (``w`` the base frequency), so the impulses are exact in the harmonic balance; a time
  integrator of the same system applies them as velocity kicks ``M dv = [G]``. ``G`` counts as
  forcing in the rules below (``forcing_affine_in_frequency``: ``dG/dt = w_exc dG/ds``).
- ``event_functions(s, q, qd, p, xp)`` -- ``None`` (default) or scalar functions of the state,
  shape ``(E,) + s.shape``, across whose zeros ``Q_nl`` may jump (contact loss: a force that
  exists only while two surfaces touch). The engine locates their zeros along the solution and
  corrects those jumps exactly (:mod:`hbgear.engine.events`); kinks need no declaration.
- ``event_zero_capacity = (8, 2)`` -- per event function and base period, the sign changes and
  the excursions between two samples (born or dying contact losses) that are located and
  corrected; more stay ``O(1/N)`` and the residual jumps where the set changes. Each costs its
  share of every residual and Jacobian evaluation: raise it only for systems whose event
  functions wiggle about zero (a relieved tooth pair near grazing contact).
- ``free_mean_dof = None`` -- a coordinate with no restoring force whose mean is pinned to 0 and
  replaced by the unknown constant force ``extra`` (e.g. an output torque fixed by periodicity);
  its two trivial Floquet multipliers at 1 are dropped.
- ``displacement_scale = 1.0``, ``force_scale = 1.0`` -- typical sizes of ``q`` and ``Q``: the
  unknowns are ``q / displacement_scale``, the residual ``R / force_scale`` (tolerances are
  relative to ``force_scale``).
- ``coefficients_independent_of_parameter = False`` -- ``M``, the breakpoints and the periodic
  stiffness and damping of ``Q_lin`` do not depend on ``p`` (only the forcing and the frequency
  do): the operator is then built once per system, and a batch of variational equations takes
  ``M`` and the breakpoints of its first member.
- ``forcing_affine_in_frequency = False`` -- ``Q_lin(s, 0, 0; p) = Fbar(p) + A(s) + w_exc(p) B(s)``
  (the forcing is then combined from two quadratures; checked at a third value).
- ``forcing_mean_affine_in_frequency = False`` -- with the above, ``Fbar(p)`` is affine in
  ``w_exc(p)`` too (a constant load, say): the residual then evaluates no force for the forcing
  (smaller compiled programs; checked at a third value, ignored if it does not hold there).
- ``nonlinear_force_uses_displacement = True`` -- ``False`` when ``Q_nl`` depends on ``q'`` only
  (its Jacobian then has no displacement blocks).
- ``piecewise_constant_coefficients = False`` -- a linear system whose homogeneous coefficients
  are constant between the breakpoints: its monodromy matrix is an exact product of matrix
  exponentials.
- ``frequency_scale(p)`` -- a typical natural frequency [rad/s] (default: ``w_exc(p)``), the
  velocity scale that balances the monodromy matrix (a similarity: it changes rounding only).
- ``neutral_multipliers(p, nu)`` -- multipliers of modes the system adds by construction and knows
  to be neutral (e.g. an undamped soft spring standing for a free rotation: ``exp(+-i w T)``),
  shape ``np.shape(p) + (t,)``; the multiplier nearest each, within
  :data:`~hbgear.engine.floquet.TRIVIAL_TOL`, is reported but left out of the stability verdict
  (default: none).
- ``input_map(p)`` -- ``None`` (default) or a matrix ``C`` ``(m, ndof)``, the same for every ``p``,
  with the promise that the force minus a linear time-invariant part, ``Q + K_0 q + C_0 q'`` for
  some constant ``K_0``, ``C_0``, depends on the state only through ``C q`` and ``C q'`` (most of
  a multi-DOF model is masses, springs and dampers; the time-varying, nonlinear terms see a few
  combinations of the coordinates). The continuation corrector then solves its Newton steps on
  the ``m (2H+1)`` ports instead of the ``ndof (2H+1)`` unknowns (:mod:`hbgear.engine.condensed`;
  ``HarmonicBalance(operator="auto")`` chooses it when it pays off). Checked at a probe state:
  moving the state along directions with ``C dq = C dq' = 0`` must change the force by the same
  amount at every phase and state, and leave the event functions unchanged.
- ``output_map(p)`` -- ``None`` (default: every coordinate) or a matrix ``(r, ndof)`` whose rows
  span the coordinates the non-LTI force acts on: ``Q + K_0 q + C_0 q'`` lies in their span for
  every state (a force derived by virtual work from what the input map sees acts along
  ``C^T``). With an input map, the condensed path then works with ``r (2H+1) x m (2H+1)``
  port blocks instead of ``ndof (2H+1) x m (2H+1)``. Checked at a probe state with the input map.
- ``arclength_mean_scales(p)`` -- ``None`` (default) or, shape ``(ndof,)``, the size of each
  coordinate's mean (in units of ``displacement_scale``) that counts as one unit of arclength in
  continuation; 1 leaves a coordinate as it is. A coordinate on a support far softer than the
  rest (e.g. a soft spring standing for a free rotation) whose mean follows a force that
  depends on the response moves by that much more per step: in plain scaled unknowns it alone
  fills the arclength and the steps crawl in ``p``. Only the metric of the continuation
  changes (its unknowns are the means divided by these sizes), not the solutions.
- ``linearization()`` / ``in_linear_regime(hb, z, p)`` -- a linear system whose variational
  equations are this system's along every solution for which ``in_linear_regime`` is true (the
  gear pair with backlash while its teeth keep contact); there the exact monodromy of the linear
  system gives the Floquet multipliers. Defaults: ``self`` for a linear system (always in its
  regime), ``None`` otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from jax.tree_util import register_dataclass

from .events import MAX_CROSSINGS, MAX_EXCURSIONS

__all__ = ["PeriodicSystem", "check_system", "Duffing"]


class PeriodicSystem:
    """Base class of every system the engine solves; see the module docstring for the contract."""

    free_mean_dof: int | None = None
    event_zero_capacity: tuple[int, int] = (MAX_CROSSINGS, MAX_EXCURSIONS)
    displacement_scale = 1.0
    force_scale = 1.0
    coefficients_independent_of_parameter: bool = False
    forcing_affine_in_frequency: bool = False
    forcing_mean_affine_in_frequency: bool = False
    nonlinear_force_uses_displacement: bool = True
    piecewise_constant_coefficients: bool = False

    @property
    def ndof(self) -> int:  # pragma: no cover - the contract
        raise NotImplementedError(f"{type(self).__name__} must define ndof")

    @property
    def is_linear(self) -> bool:  # pragma: no cover - the contract
        raise NotImplementedError(f"{type(self).__name__} must define is_linear")

    def mass_matrix(self, p, xp=np):  # pragma: no cover - the contract
        raise NotImplementedError(f"{type(self).__name__} must define mass_matrix(p, xp)")

    def excitation_frequency(self, p):  # pragma: no cover - the contract
        raise NotImplementedError(f"{type(self).__name__} must define excitation_frequency(p)")

    def force(self, s, q, qd, p, part, extra, xp=np):  # pragma: no cover - the contract
        raise NotImplementedError(f"{type(self).__name__} must define force(s, q, qd, p, part, extra, xp)")

    def breakpoints(self, p, xp=np):
        """Phases in [0, 1] where the force may jump (none by default)."""
        return xp.zeros(0)

    def derivative_forcing(self, s, p, xp=np):
        """``G(s; p)`` whose time derivative is part of the linear forcing, or ``None`` (default)."""
        return None

    def frequency_scale(self, p):
        """A typical natural frequency [rad/s] (balancing of monodromy matrices); ``w_exc(p)``."""
        return self.excitation_frequency(p)

    def neutral_multipliers(self, p, nu: int = 1):
        """Known neutral multipliers over the base period (``nu`` excitation periods), shape
        ``np.shape(p) + (t,)``; none by default."""
        return np.zeros(np.shape(p) + (0,), dtype=complex)

    def arclength_mean_scales(self, p):
        """Sizes of the coordinates' means that count as one unit of arclength (module doc);
        ``None``: the scaled unknowns as they are."""
        return None

    def linearization(self) -> PeriodicSystem | None:
        """The linear system whose variational equations are this one's in its linear regime."""
        return self if self.is_linear else None

    def in_linear_regime(self, hb, z, p) -> bool:
        """Whether the solution `z` (scaled unknowns of `hb`) at `p` stays in the regime where
        :meth:`linearization` holds."""
        return True

    def event_functions(self, s, q, qd, p, xp=np):
        """Functions across whose zeros ``Q_nl`` may jump, shape ``(E,) + s.shape``, or ``None`` (default)."""
        return None

    def input_map(self, p):
        """``C`` ``(m, ndof)``: the combinations of the state the non-LTI force sees, or ``None`` (default)."""
        return None

    def output_map(self, p):
        """``(r, ndof)``: rows spanning the coordinates the non-LTI force acts on, or ``None`` (default: all)."""
        return None


def check_system(system, p) -> None:
    """Check `system` against the contract at parameter `p` (numpy; a few force evaluations).

    **Raises:** ``TypeError`` if it is not a :class:`PeriodicSystem`; ``ValueError`` naming the
    first broken rule: ``ndof`` not a positive integer, a mass matrix, force, derivative forcing or
    event functions of the wrong shape or not finite, a ``free_mean_dof`` out of range, breakpoints not a finite 1-D array,
    ``is_linear = True`` with a nonzero nonlinear part, or an ``input_map`` whose promise fails at a probe state.
    """
    if not isinstance(system, PeriodicSystem):
        raise TypeError(f"{type(system).__name__} is not a hbgear.PeriodicSystem (subclass it: the class "
                        "docstring of hbgear.engine.system lists the contract)")
    name = type(system).__name__
    n = system.ndof
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"{name}.ndof = {n!r}: a positive integer")
    mass = np.asarray(system.mass_matrix(p, np), dtype=float)
    if mass.shape != (n, n) or not np.all(np.isfinite(mass)):
        raise ValueError(f"{name}.mass_matrix(p) has shape {mass.shape}: ({n}, {n}) finite values (ndof = {n})")
    k = system.free_mean_dof
    if k is not None and not (isinstance(k, (int, np.integer)) and 0 <= k < n):
        raise ValueError(f"{name}.free_mean_dof = {k!r}: None or a coordinate index 0 .. {n - 1}")
    bp = np.asarray(system.breakpoints(p, np), dtype=float)
    if bp.ndim != 1 or not np.all(np.isfinite(bp)):
        raise ValueError(f"{name}.breakpoints(p) = {bp!r}: a 1-D array of finite phases")
    s = np.array([0.1234, 0.5678])
    rng = np.random.default_rng(0)
    q = rng.standard_normal((n, 2)) * float(system.displacement_scale)
    qd = rng.standard_normal((n, 2)) * float(system.displacement_scale) * float(system.excitation_frequency(p))
    for part in ("linear", "nonlinear", "all"):
        f = np.asarray(system.force(s, q, qd, p, part, 0.0, np), dtype=float)
        if f.shape != (n, 2) or not np.all(np.isfinite(f)):
            raise ValueError(f"{name}.force(s, q, qd, p, {part!r}, ...) returned shape {f.shape} for s of shape (2,): "
                             f"({n}, 2) finite values")
    g = system.derivative_forcing(s, p, np)
    if g is not None and (np.shape(g) != (n, 2) or not np.all(np.isfinite(np.asarray(g, dtype=float)))):
        raise ValueError(f"{name}.derivative_forcing(s, p) returned shape {np.shape(g)} for s of shape (2,): "
                         f"None or ({n}, 2) finite values")
    e = system.event_functions(s, q, qd, p, np)
    if e is not None and (np.ndim(e) != 2 or np.shape(e)[1:] != (2,) or not np.all(np.isfinite(np.asarray(e, dtype=float)))):
        raise ValueError(f"{name}.event_functions(s, q, qd, p) returned shape {np.shape(e)} for s of shape (2,): "
                         "None or (E, 2) finite values")
    if system.is_linear:
        f = np.asarray(system.force(s, q, qd, p, "nonlinear", 0.0, np), dtype=float)
        if np.max(np.abs(f)) > 1e-12 * float(system.force_scale):
            raise ValueError(f"{name}.is_linear is True but its nonlinear force part is {np.max(np.abs(f)):.3g} "
                             "at a probe state (declare is_linear = False)")
    if system.input_map(p) is not None:
        from .condensed import check_input_map

        check_input_map(system, p)


@register_dataclass
@dataclass(frozen=True)
class Duffing(PeriodicSystem):
    r"""``x'' + c x' + k x + a x^3 = f cos(w t)``; the parameter is ``w`` [rad/s].

    A generic check of the engine and of continuation (known backbone and jump frequencies).
    """

    damping: float = 0.02
    stiffness: float = 1.0
    cubic: float = 0.1
    forcing: float = 0.05

    ndof = 1
    is_linear = False
    coefficients_independent_of_parameter = True
    forcing_affine_in_frequency = True
    forcing_mean_affine_in_frequency = True  # f cos(w t): no constant load at all

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def breakpoints(self, p, xp=np):
        return xp.zeros(1)

    def force(self, s, q, qd, p, part, extra, xp=np):
        linear = self.forcing * xp.cos(2 * np.pi * s) - self.stiffness * q[0] - self.damping * qd[0]
        nonlinear = -self.cubic * q[0] ** 3
        if part == "linear":
            return xp.stack([linear])
        if part == "nonlinear":
            return xp.stack([nonlinear])
        return xp.stack([linear + nonlinear])
