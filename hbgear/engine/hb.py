r"""Harmonic-balance residual, exact Jacobians and Hill matrices (MODEL.md section 5).

Balanced equation, for a system ``M q'' = Q_lin(s, q, q') + Q_nl(s, q, q')`` (see
:mod:`hbgear.gear.system`) on the base frequency ``w = w_exc / nu``, harmonics ``0..H``::

    R(X) = (M (x) D^2 + K_conv + C_conv (I (x) D)) X - F - P Q_nl(E X, E (I (x) D) X) = 0

- ``X``: real Fourier coefficients, coordinate-major, each ``[a_0, a_1, b_1, ..., a_H, b_H]``
  (:mod:`hbgear.engine.fourier`), scaled by the system's ``displacement_scale``; ``R`` is scaled by
  ``force_scale``.
- ``K_conv``, ``C_conv``, ``F``: Galerkin matrices / vector of the affine periodic part
  ``Q_lin = F(s) - K(s) q - C(s) q'``, from its exact Fourier coefficients (composite
  Gauss--Legendre between the breakpoints, :mod:`hbgear.engine.quadrature`): no sampling error.
  ``F`` includes ``dG/dt`` of a system's ``derivative_forcing`` ``G`` (impulses at its jumps
  included) as ``i m w G_m``.
- ``E``/``P``: synthesis on / projection from ``N`` uniform samples of the base period (AFT),
  with the jumps of ``Q_nl`` at the breakpoints (pairs entering or leaving contact) taken out
  of the samples and put back with their exact coefficients (:meth:`HarmonicBalance._sample_points`):
  ``O(1/N^2)`` instead of the ``O(1/N)`` aliasing of a sampled jump; likewise the jumps at the
  zeros of a system's ``event_functions``, located along the solution (:mod:`hbgear.engine.events`).
- A ``free_mean_dof`` has its mean pinned to zero; its slot in ``X`` holds the constant force
  unknown (e.g. the reaction output torque) instead.

Jacobians come from ``jax.jacfwd``: with respect to ``X`` and to the parameter ``p``.
The Hill eigenproblem of a solution is ``(J + lam D1 + lam^2 D2) v = 0`` with
``D2 = M (x) I`` and ``D1 = 2 M (x) D + dR/d(velocity coefficients)``.

Many harmonics: from :data:`STRUCTURED_MIN_SIZE` unknowns on, :meth:`HarmonicBalance.prepare`
builds the structured path instead (:mod:`hbgear.engine.structured`: the same residual by FFT
products, Newton steps by preconditioned GMRES, no ``(size x size)`` array);
:meth:`HarmonicBalance.residual_and_linearization` hands Newton whichever Jacobian the size chose,
and the continuation corrector (:func:`residual_functions`) gets the Jacobian as a
:class:`~hbgear.engine.structured.KrylovJacobian`, its bordered systems solved by GMRES inside the
compiled corrector.

Many coordinates, few of them nonlinear: for a system that declares an ``input_map`` the
prepared pieces hold the condensed path (:mod:`hbgear.engine.condensed`, chosen by
:meth:`HarmonicBalance.prepare`): the residual's linear part as the mean operator plus its port
part, and for the continuation corrector (:func:`residual_functions`) the Jacobian as a
:class:`~hbgear.engine.condensed.PortJacobian` whose bordered systems are solved by Woodbury on
the ports. :meth:`HarmonicBalance.residual_and_jacobians` and the Hill matrices stay dense.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import condensed, events, fourier, structured
from .arrays import device_array
from .caching import BoundedCache
from .quadrature import LatticeRule, lattice_coefficients, lattice_rule, mesh_period_rule
from .persistent import persistent
from .typed_jit import typed_jit


__all__ = ["HarmonicBalance", "Prepared", "FrozenOperator", "ForcingPieces", "JumpLayout", "residual_functions",
           "jacobian_is_structured",
           "STRUCTURED_MIN_SIZE", "CONDENSED_MIN_SIZE"]

#: From this many unknowns ``n (2H+1)`` on, ``operator="auto"`` takes the structured path
#: (:mod:`hbgear.engine.structured`: FFT products, GMRES with the band preconditioner,
#: no ``(size x size)`` array); below it the dense Jacobian and its LU. Measured on the NLTV gear
#: pair at 200 rpm (``benchmarks/bench_large_harmonics.py``, 2 cores, one BLAS thread), one
#: Newton step dense / structured with the band preconditioner: 1.4 / 2.8 ms at 258 unknowns
#: (H = 64), 5.1 / 3.1 ms at 514, 29.4 / 4.6 ms at 1026, 199 / 7.7 ms at 2050; a continuation
#: point (`examples/low_speed_nltv.toml`, 200-230 rpm, 107 points; dense chord LU / bordered
#: GMRES): 6.0 / 6.2 ms at 514, 39.2 / 13.1 ms at 1026, 204 / 27 ms at 2050. The crossover lies
#: near 520 unknowns; the rule stays at 1000 so that the gear pair's sizes of the automatic
#: harmonics (130, 258, 514) keep the dense path, where Hill's method, which needs the dense
#: Jacobian, keeps its frozen matrices, and the condensed path keeps the multi-DOF models below
#: it; above it the dense LU grows like size^3, its matrices like size^2.
STRUCTURED_MIN_SIZE = 1000

#: From this many unknowns on (and below :data:`STRUCTURED_MIN_SIZE`), ``operator="auto"`` takes
#: the condensed path (:mod:`hbgear.engine.condensed`) for a system that declares an
#: ``input_map`` whose ports ``m (2H+1) + 2`` are at most :data:`CONDENSED_MAX_PORTS` of the
#: unknowns (its LU then costs at most ~40 % of the dense one). Measured in
#: ``benchmarks/bench_bearings.py``.
CONDENSED_MIN_SIZE = 200
CONDENSED_MAX_PORTS = 0.75


class ForcingPieces(NamedTuple):
    """The forcing as ``F_hat(p) = at_a + (w - w_a) slope + e_mean (F(s_*; p) - point_a - (w - w_a)
    point_slope)`` (:meth:`HarmonicBalance._forcing_pieces`); ``w`` the excitation frequency.
    ``point_a``, ``point_slope``, ``s_star`` are ``None`` when the mean is affine in ``w`` too:
    then ``F_hat(p) = at_a + (w - w_a) slope``."""

    at_a: Any
    slope: Any
    w_a: Any
    point_a: Any
    point_slope: Any
    s_star: Any


class FrozenOperator(NamedTuple):
    """``L(w) = a0 + w a1 + w^2 a2`` and ``C_conv`` (flattened, SI) with the forcing pieces, when
    the coefficients do not depend on the parameter (:meth:`HarmonicBalance._frozen_operator`)."""

    a0: Any
    a1: Any
    a2: Any
    damping: Any
    forcing: ForcingPieces | None


class JumpLayout(NamedTuple):
    """Where and how the jumps of ``Q_nl`` are taken out of the AFT samples
    (:meth:`HarmonicBalance._jump_layout`): mesh phases just after and just before each candidate
    ``(2C,)``, synthesis rows ``(C, 2H+1)``, ``1/multiplicity`` ``(C,)``, ``B_hat_c - P B_c``
    ``(C, 2H+1)``."""

    sides: Any
    at_c: Any
    weight: Any
    delta: Any


class Prepared(NamedTuple):
    """What a discretisation needs of a system besides its parameters, built once by
    :meth:`HarmonicBalance.prepare` and passed to every evaluation (a pytree: it goes into
    compiled functions as an argument).

    **Fields:** `nodes` ``(n,)`` mesh phases of the quadrature rule; `kernel_cos`, `kernel_sin`
    ``(R+1, n)`` its Fourier kernel with the weights folded in (``None`` on the structured path);
    `frozen` the parameter-independent dense operator (or ``None``); `jumps` the jump layout (or
    ``None``: built in the trace); `structured` the pieces of the structured path
    (:class:`~hbgear.engine.structured.StructuredOperator`, or ``None``: the dense path);
    `condensed` the pieces of the condensed path (:class:`~hbgear.engine.condensed.CondensedOperator`,
    or ``None``): the residual is the dense path's, the continuation corrector's Jacobian a
    :class:`~hbgear.engine.condensed.PortJacobian`.
    """

    nodes: Any
    kernel_cos: Any
    kernel_sin: Any
    frozen: FrozenOperator | None = None
    jumps: JumpLayout | None = None
    structured: structured.StructuredOperator | None = None
    condensed: condensed.CondensedOperator | None = None

    @property
    def rule(self):
        """``(nodes, kernel_cos, kernel_sin)``, or the :class:`~hbgear.engine.quadrature.LatticeRule`
        of the structured path (its first entry the nodes too)."""
        if self.structured is not None:
            return self.structured.lattice
        return self.nodes, self.kernel_cos, self.kernel_sin

    @property
    def forcing_pieces(self) -> ForcingPieces | None:
        """The frozen forcing pieces of either path (or ``None``: quadrature at every call)."""
        holder = self.structured if self.structured is not None else self.frozen
        return None if holder is None else holder.forcing


def _kept_method(method):
    """``typed_jit`` with the ``HarmonicBalance`` (``self``, frozen settings) static, its traced
    programs kept on disk when a directory is enabled (:mod:`hbgear.engine.persistent`)."""
    return persistent(typed_jit(method, static_argnums=0), f"hb{method.__name__}", f"engine.hb.{method.__name__}",
                      static_argnums=0)


@dataclass(frozen=True)
class HarmonicBalance:
    """Discretisation settings; methods take the system (a pytree) and the parameter.

    **Arguments:** `ndof`: coordinates; `harmonics`: ``H``; `nu`: 1 (harmonics of the
    excitation) or 2 (adds half orders); `samples`: AFT samples per base period ``N``;
    `operator`: ``"dense"`` (Jacobian matrices, LU), ``"structured"`` (FFT products and GMRES,
    :mod:`hbgear.engine.structured`), ``"condensed"`` (the continuation corrector solves on the
    ports of a system's ``input_map``, :mod:`hbgear.engine.condensed`) or ``"auto"`` (structured
    from :data:`STRUCTURED_MIN_SIZE` unknowns on; condensed from :data:`CONDENSED_MIN_SIZE` for a
    system with an input map that pays off).
    """

    ndof: int
    harmonics: int
    nu: int = 1
    samples: int = 256
    operator: str = "auto"

    def __post_init__(self):
        if self.operator not in ("auto", "dense", "structured", "condensed"):
            raise ValueError(f"operator must be 'auto', 'dense', 'structured' or 'condensed', got {self.operator!r}")
        if self.samples < 2 * self.harmonics + 2:
            raise ValueError(f"samples ({self.samples}) must be >= 2 H + 2 = {2 * self.harmonics + 2}")
        if self.samples % self.nu:
            raise ValueError("samples must be a multiple of nu")

    @property
    def block(self) -> int:
        return fourier.basis_size(self.harmonics)

    @property
    def size(self) -> int:
        return self.ndof * self.block

    @property
    def structured(self) -> bool:
        """Whether :meth:`prepare` builds the structured path (:attr:`operator`, size rule)."""
        return self.operator == "structured" or (self.operator == "auto" and self.size >= STRUCTURED_MIN_SIZE)

    def base_frequency(self, system, p):
        return system.excitation_frequency(p) / self.nu

    # -- the prepared operator: built once per system, passed along -------------------------
    @property
    def max_mesh_order(self) -> int:
        """Highest mesh order ``R = ceil(2H / nu)`` whose coefficients the operator needs."""
        return -(-2 * self.harmonics // self.nu)

    def prepare(self, system, p=1.0) -> Prepared:
        """The :class:`Prepared` pieces of this discretisation for `system`.

        The mesh-period rule and its Fourier kernel depend on the breakpoints only (for the gear
        pair: the contact ratio and the contact path), so they are computed once in numpy and
        reused; evaluating ``exp(-2 pi i r s)`` at thousands of nodes would otherwise dominate
        every residual. When the system declares parameter-independent coefficients, the
        operator pieces (:meth:`_frozen_operator`) and the jump layout (:meth:`_frozen_jumps`)
        come with it. The pieces are cached on their content (bounded); a caller that loops
        (Newton, continuation) prepares once and passes the result to every evaluation.

        Under a trace of the system itself (an outer ``jit``/``vmap`` over systems) the rule is
        built in the trace and nothing is frozen (the dense path, whatever the size). On the
        structured path (:attr:`structured`) no kernel and no dense operator are built: the
        rule's structure (:func:`~hbgear.engine.quadrature.lattice_rule`) and, when frozen,
        the periodic coefficients (:func:`~hbgear.engine.structured.prepare_structured`). A system
        with ``event_functions`` takes the dense path at any size (its Jacobian carries the
        moving jumps, :func:`~hbgear.engine.events.jump_jacobian`); ``operator='structured'``
        is refused for it.
        """
        if _has_tracer((system, p)):
            s, w = mesh_period_rule(system.breakpoints(p, jnp), self.max_mesh_order, jnp)
            phase = 2 * np.pi * jnp.arange(self.max_mesh_order + 1)[:, None] * s[None]
            return Prepared(s, jnp.cos(phase) * w, jnp.sin(phase) * w)
        # concrete arrays even when first asked for inside a trace (a compiled caller's first
        # call): the caches must never hold tracers
        with jax.ensure_compile_time_eval():
            if self.structured and events.declared(system, p):
                if self.operator == "structured":
                    raise ValueError("operator='structured' does not carry the jumps at a system's event_functions "
                                     "(contact loss with friction); use operator='dense' or 'auto'")
            elif self.structured:
                breakpoints = _breakpoint_key(system, p)
                lattice = _RULES.get_or_make((breakpoints, self.max_mesh_order, "lattice"),
                                             lambda: self._lattice(system, p))
                pieces = _FROZEN.get_or_make(self._content_key(system, "structured", breakpoints),
                                             lambda: structured.prepare_structured(self, system, p, *lattice))
                return Prepared(pieces.lattice.nodes, None, None, None, self._frozen_jumps(system), pieces)
            rule = _RULES.get_or_make((_breakpoint_key(system, p), self.max_mesh_order),
                                      lambda: self._rule(system, p))
            return Prepared(*rule, self._frozen_operator(system, p, rule), self._frozen_jumps(system), None,
                            self._condensed(system, p, rule))

    def _condensed(self, system, p, rule) -> condensed.CondensedOperator | None:
        """The :class:`~hbgear.engine.condensed.CondensedOperator` of a system that declares an
        ``input_map`` (checked at a probe state, :func:`~hbgear.engine.condensed.check_input_map`),
        when :attr:`operator` asks for it or, ``"auto"``, when it pays off: at least
        :data:`CONDENSED_MIN_SIZE` unknowns and ports ``m (2H+1) + 2`` at most
        :data:`CONDENSED_MAX_PORTS` of them.
        Else ``None`` (the dense path)."""
        if self.operator not in ("auto", "condensed"):
            return None
        forced = self.operator == "condensed"
        declared = system.input_map(p)
        if declared is None or not self._toeplitz_ok(system):
            if forced:
                raise ValueError("operator='condensed' needs a system with an input_map and samples > 4 H")
            return None

        def make():
            basis = condensed.port_basis(declared, self.ndof)
            if basis is None:
                return None
            ports = basis[0].shape[0]
            if not forced and not (self.size >= CONDENSED_MIN_SIZE
                                   and ports * self.block + 2 <= CONDENSED_MAX_PORTS * self.size):
                return None
            condensed.check_input_map(system, p, basis)
            outputs = condensed.output_basis(system, p)
            pieces = ()
            if system.coefficients_independent_of_parameter:
                rule_np = tuple(np.asarray(a) for a in rule)
                _, stiffness, damping = self._periodic_coefficients(system, p, rule_np, np)
                pieces = jax.device_put(condensed.port_operator(stiffness, damping, basis[0], outputs, self.harmonics,
                                                                np))
            return condensed.CondensedOperator(jax.device_put(basis[0]), jax.device_put(outputs), *pieces)

        return _FROZEN.get_or_make(self._content_key(system, "condensed", rule[0].shape), make)

    def _rule(self, system, p):
        """``(nodes, kernel_cos, kernel_sin)`` of the mesh-period rule, weights folded in (device arrays)."""
        s, w = mesh_period_rule(np.asarray(_breakpoint_key(system, p)), self.max_mesh_order)
        phase = 2 * np.pi * np.outer(np.arange(self.max_mesh_order + 1), s)
        return jax.device_put((s, np.cos(phase) * w, np.sin(phase) * w))  # no compiled copy per array

    def _lattice(self, system, p):
        """The :class:`~hbgear.engine.quadrature.LatticeRule` of :meth:`_rule`'s nodes, in numpy and
        as device arrays."""
        rule = lattice_rule(np.asarray(_breakpoint_key(system, p)), self.max_mesh_order)
        return rule, jax.device_put(rule)  # no compiled copy per array (jnp.asarray here: one each)

    def _frozen_jumps(self, system) -> JumpLayout | None:
        """The jump layout of :meth:`_sample_points` (device arrays) when the breakpoints do not
        depend on the parameter, else ``None``. Given with the prepared pieces, a compiled caller
        that takes the system as an argument does not rebuild it (a projection of ``2C``
        sawtooth signals) at every residual evaluation."""
        if not system.coefficients_independent_of_parameter:
            return None
        return JumpLayout(*jax.device_put(tuple(self._jump_layout(system, 1.0))))

    def _frozen_operator(self, system, p, rule) -> FrozenOperator | None:
        """The parameter-independent pieces of the linear operator, when the system declares them so.

        For a speed sweep of the gear pair ``M`` and the periodic stiffness and damping
        coefficients do not depend on the speed (only the forcing and ``D(w) = w D_1`` do), so

            L(w) = M (x) D^2 + K_conv + C_conv (I (x) D) = A_0 + w A_1 + w^2 A_2,
            A_0 = K_conv,  A_1 = C_conv (I (x) D_1),  A_2 = M (x) D_1^2,

        are built once per system (cached on the system's content) and each evaluation combines
        three matrices (or applies them to ``x``) instead of rebuilding ``L``.

        **Returns:** ``None`` or a :class:`FrozenOperator`, matrices flattened ``(size, size)`` in SI.
        """
        if not system.coefficients_independent_of_parameter:
            return None
        key = self._content_key(system, rule[0].shape)

        def make():
            # in numpy: a one-off computation of a few ms, which compiled for ~2 s in XLA
            rule_np = tuple(np.asarray(a) for a in rule)
            blocks = tuple(np.asarray(b) for b in self._blocks(system, p, rule_np))
            blocks = jax.device_put(blocks)  # not jnp.asarray: no compiled copy per array
            return FrozenOperator(*blocks, self._forcing_pieces(system, rule_np))

        return _FROZEN.get_or_make(key, make)

    def _content_key(self, system, *more) -> tuple:
        """A hashable key of this discretisation and the system's content (its leaves' bytes)."""
        leaves, treedef = jax.tree_util.tree_flatten(system)
        return (self, treedef, tuple(np.asarray(leaf).tobytes() for leaf in leaves)) + more

    def _forcing_pieces(self, system, rule) -> ForcingPieces | None:
        r"""Pieces of the forcing vector when it is affine in the excitation frequency up to a
        constant (in ``s``) term, ``F(s; p) = Fbar(p) + A(s) + w_exc(p) B(s)`` (the system says
        so with ``forcing_affine_in_frequency``; checked here at a third parameter value).

        Then, from full quadratures at ``p_a``, ``p_b`` and point values ``f = F(s_*; .)`` at one
        node ``s_*``, with ``lam = (w - w_a) / (w_b - w_a)``:

            F_hat(p) = F_hat_a + lam (F_hat_b - F_hat_a) + e_mean (F(s_*; p) - f_a - lam (f_b - f_a))

        exactly: the harmonics are affine in ``w``, and the point value gives ``Fbar(p)``. A call
        then evaluates ``F`` at one node instead of at every quadrature node.

        When the system declares ``forcing_mean_affine_in_frequency`` (``Fbar`` affine in ``w``
        too: a constant load, say) and the point values confirm it at ``p_c``, the point term is
        left out (``point_a``, ``point_slope``, ``s_star`` ``None``): no evaluation of the force
        is traced into the residual, which is then a smaller program (the LTV example's
        corrector: its trace 0.38 -> 0.22 s, its compilation 1.06-1.26 -> 0.88-0.96 s).

        **Returns:** ``None`` or the :class:`ForcingPieces` ``(F_hat_a, dF_hat/dw, w_a, f_a, df/dw, s_*)``.
        """
        if not system.forcing_affine_in_frequency:
            return None
        # from p_a = 1, p_b = 3, checked against the quadrature at p_c = 2
        s_star = rule[0][:1]

        def at(p):
            forcing, _, _ = self._periodic_coefficients(system, p, rule, np, forcing_only=True)
            real = fourier.coefficients_to_real(forcing, self.harmonics, np).reshape(self.size)
            return real, self._point_forcing(system, p, s_star, np), system.excitation_frequency(p)

        (f_a, pt_a, w_a), (f_b, pt_b, w_b), (f_c, pt_c, w_c) = at(1.0), at(3.0), at(2.0)
        scale = np.max(np.abs(f_c)) + 1e-300
        pieces = ForcingPieces(f_a, (f_b - f_a) / (w_b - w_a), w_a, pt_a, (pt_b - pt_a) / (w_b - w_a), s_star)
        if system.forcing_mean_affine_in_frequency:
            off_line = np.max(np.abs(pt_c - pt_a - (w_c - w_a) * pieces.point_slope))
            if np.isfinite(off_line) and off_line <= 1e-11 * (scale + np.max(np.abs(pt_c))):
                pieces = ForcingPieces(pieces.at_a, pieces.slope, w_a, None, None, None)
        error = np.max(np.abs(self._combined_forcing(system, 2.0, pieces, np) - f_c))
        if not (np.isfinite(error) and error <= 1e-11 * scale):
            return None  # the declared structure does not hold: full quadrature every call
        return ForcingPieces(*jax.device_put(tuple(None if a is None else np.asarray(a) for a in pieces)))

    def _point_forcing(self, system, p, s_star, xp=jnp):
        zero = xp.zeros((self.ndof, 1))
        return system.force(s_star, zero, zero, p, "linear", 0.0, xp)[:, 0]

    def _combined_forcing(self, system, p, pieces, xp=jnp):
        f_a, d_hat, w_a, pt_a, d_pt, s_star = pieces
        dw = system.excitation_frequency(p) - w_a
        if s_star is None:  # the mean is affine in w too (declared, checked in _forcing_pieces)
            return f_a + dw * d_hat
        mean_fix = self._point_forcing(system, p, s_star, xp) - pt_a - dw * d_pt  # (ndof,)
        mean = np.zeros(self.size)
        mean[:: self.block] = 1.0  # the a_0 slot of each coordinate
        return f_a + dw * d_hat + xp.repeat(mean_fix, self.block) * mean

    def _blocks(self, system, p, rule):
        """``(A_0, A_1, A_2, C_conv)`` of :meth:`_frozen_operator` (numpy)."""
        H = self.harmonics
        _, stiffness, damping = self._periodic_coefficients(system, p, rule, np)
        k_conv = fourier.convolution_matrix(stiffness, H, np)
        c_conv = fourier.convolution_matrix(damping, H, np)
        d1 = fourier.derivative_matrix(H, 1.0, np)
        mass = np.asarray(system.mass_matrix(p, np), dtype=float)
        a2 = mass[:, :, None, None] * (d1 @ d1)[None, None] + 0.0 * k_conv
        flat = lambda b: self._flatten(b, np)  # noqa: E731
        return flat(k_conv), flat(c_conv @ d1[None, None]), flat(a2), flat(c_conv)

    def _periodic_coefficients(self, system, p, rule, xp=jnp, forcing_only=False):
        """Complex base-harmonic coefficients ``(F, K, C)`` of ``Q_lin = F - K q - C q'``.

        ``Q_lin`` is affine in ``(q, q')``, so probing it at ``0`` and at unit vectors gives its
        coefficients exactly; one vmapped evaluation over the probes at all quadrature nodes
        (a loop over them in numpy). `rule`: ``(nodes, kernel_cos, kernel_sin)`` or a
        :class:`~hbgear.engine.quadrature.LatticeRule` (chirp transforms instead of the kernel);
        `forcing_only`: probe at 0 alone (the stiffness and damping returned are then empty).
        """
        n, H, nu = self.ndof, self.harmonics, self.nu
        s = rule[0]
        eye = xp.zeros((0, n)) if forcing_only else xp.eye(n)
        probes_q = xp.concatenate([xp.zeros((1, n)), eye, xp.zeros_like(eye)])
        probes_v = xp.concatenate([xp.zeros((1, n)), xp.zeros_like(eye), eye])
        ones = xp.ones_like(s)

        def force(qv, vv):
            return system.force(s, qv[:, None] * ones, vv[:, None] * ones, p, "linear", 0.0, xp)

        if xp is np:
            values = np.stack([np.asarray(force(a, b), dtype=float) for a, b in zip(probes_q, probes_v)])
        else:
            values = jax.vmap(force)(probes_q, probes_v)  # (1+2n, n, nodes)
        if isinstance(rule, LatticeRule):
            coeff = lattice_coefficients(values, rule, xp)
        else:
            coeff = values @ rule[1].T - 1j * (values @ rule[2].T)
        coeff = fourier.mesh_to_base(coeff, nu, 2 * H + 1, xp)  # (1+2n, n, 2H+1)
        forcing = coeff[0]
        stiffness = xp.transpose(forcing[None] - coeff[1 : 1 + n], (1, 0, 2))  # (n_row, n_col, .)
        damping = xp.transpose(forcing[None] - coeff[1 + n :], (1, 0, 2))
        return forcing + self._derivative_forcing(system, p, rule, xp), stiffness, damping

    def _derivative_forcing(self, system, p, rule, xp=jnp):
        """Base-harmonic coefficients ``i m w G_m`` of the system's ``dG/dt`` (its
        ``derivative_forcing``, jumps included as impulses), shape ``(n, 2H+1)``; 0 without one.

        ``G_m`` come from the quadrature between the breakpoints (exact for a piecewise smooth
        ``G``), so the impulses ``[G] delta(t - t_c)`` enter with their exact coefficients.
        """
        s, kernel_cos, kernel_sin = rule[:3]
        g = system.derivative_forcing(s, p, xp)
        if g is None:
            return 0.0
        g = xp.asarray(g, dtype=float)
        coeff = fourier.mesh_to_base(g @ kernel_cos.T - 1j * (g @ kernel_sin.T), self.nu, 2 * self.harmonics + 1, xp)
        order = xp.arange(2 * self.harmonics + 1)
        return 1j * order * self.base_frequency(system, p) * coeff

    def linear_operator(self, system, p, prepared=None):
        """``(L, F, C_conv)`` in SI: ``L = M D^2 + K_conv + C_conv D``, forcing vector ``F``."""
        H = self.harmonics
        prepared = self.prepare(system) if prepared is None else prepared
        frozen = prepared.frozen
        if frozen is not None:
            w = self.base_frequency(system, p)
            return frozen.a0 + w * frozen.a1 + w**2 * frozen.a2, self._forcing(system, p, prepared), frozen.damping
        forcing, stiffness, damping = self._coefficients(system, p, prepared)
        k_conv = fourier.convolution_matrix(stiffness, H, jnp)  # (n, n, B, B)
        c_conv = fourier.convolution_matrix(damping, H, jnp)
        w = self.base_frequency(system, p)
        mass = system.mass_matrix(p, jnp)
        # C D and D^2 without the (B x B) products (O(B^3) per block): D moves and scales columns,
        # D^2 is diagonal, -(k w)^2 on a_k and b_k; the same numbers as the products
        kw = w * jnp.arange(1, H + 1)
        d2 = jnp.diag(jnp.concatenate([jnp.zeros(1), jnp.repeat(kw * -kw, 2)]))
        op = mass[:, :, None, None] * d2[None, None] + k_conv - fourier.differentiate(c_conv, H, w, jnp)
        return self._flatten(op), forcing, self._flatten(c_conv)

    def _coefficients(self, system, p, prepared):
        """``(F, K, C)``: the forcing vector (real, SI) and the complex coefficients ``(n, n, 2H+1)``
        of ``K(s)``, ``C(s)``: those the structured path keeps when frozen, else by quadrature."""
        pieces = prepared.structured
        if pieces is not None and pieces.stiffness is not None:
            return self._forcing(system, p, prepared), pieces.stiffness, pieces.damping
        forcing, stiffness, damping = self._periodic_coefficients(system, p, prepared.rule)
        return fourier.coefficients_to_real(forcing, self.harmonics, jnp).reshape(self.size), stiffness, damping

    def _linear_response(self, x, p, system, prepared):
        """``L x - F`` in SI; with the frozen pieces as three matrix-vector products, on the
        structured path as FFT products (:func:`~hbgear.engine.structured.linear_response`)."""
        if prepared.structured is not None:
            return structured.linear_response(self, x, p, system, prepared)
        if prepared.condensed is not None:  # A(w) x + (P_K + w P_C)(C x): O(n B (n + m B))
            k_bar, c_bar, k_ports, c_ports, _, _ = self._port_operator(system, p, prepared)
            w = self.base_frequency(system, p)
            xc = x.reshape(self.ndof, self.block)
            v1 = fourier.differentiate(xc, self.harmonics, 1.0, jnp)
            mass = system.mass_matrix(p, jnp)
            mean = k_bar @ xc + w * (c_bar @ v1) + w**2 * (mass @ fourier.differentiate(v1, self.harmonics, 1.0, jnp))
            pieces = prepared.condensed
            y = (pieces.ports @ xc).T.reshape(-1)  # harmonic-major (condensed.port_matrix)
            v = (k_ports @ y + w * (c_ports @ y)).reshape(self.block, -1)
            ports = (pieces.outputs.T @ v.T).reshape(-1)  # (O (x) I) v, coordinate-major
            return mean.reshape(self.size) + ports - self._forcing(system, p, prepared)
        frozen = prepared.frozen
        if frozen is None:
            lin, forcing, _ = self.linear_operator(system, p, prepared)
            return lin @ x - forcing
        w = self.base_frequency(system, p)
        return frozen.a0 @ x + w * (frozen.a1 @ x) + w**2 * (frozen.a2 @ x) - self._forcing(system, p, prepared)

    def _forcing(self, system, p, prepared):
        """The forcing vector ``F`` (real coefficients, SI): combined from the frozen pieces when
        there are some (:meth:`_forcing_pieces`), else by quadrature."""
        if prepared.forcing_pieces is not None:
            return self._combined_forcing(system, p, prepared.forcing_pieces)
        forcing, _, _ = self._periodic_coefficients(system, p, prepared.rule)
        return fourier.coefficients_to_real(forcing, self.harmonics, jnp).reshape(self.size)

    def _flatten(self, blocks, xp=jnp):
        return xp.transpose(blocks, (0, 2, 1, 3)).reshape(self.size, self.size)

    # -- residual --------------------------------------------------------------------------------
    def _split(self, system, z):
        """Scaled unknowns -> (X in SI, extra force)."""
        x = z * system.displacement_scale
        k = system.free_mean_dof
        if k is None:
            return x, 0.0
        slot = k * self.block
        extra = z[slot] * system.force_scale
        return x.at[slot].set(0.0), extra

    def decode(self, system, z):
        """Scaled unknowns ``z`` ``(..., size)`` -> ``(coefficients, extra)`` in SI (numpy):
        coefficients ``(..., ndof, 2H+1)`` (a free coordinate's mean slot zeroed) and the constant
        force unknown ``(...)`` it held (zeros without a ``free_mean_dof``)."""
        z = np.asarray(z, dtype=float)
        x = z * float(system.displacement_scale)
        extra = np.zeros(z.shape[:-1])
        k = system.free_mean_dof
        if k is not None:
            slot = k * self.block
            extra = z[..., slot] * float(system.force_scale)
            x = x.copy()
            x[..., slot] = 0.0
        return x.reshape(z.shape[:-1] + (self.ndof, self.block)), extra

    def _nonlinear(self, x, velocity, extra, p, system, layout=None):
        """``P Q_nl(E x, E v)`` in SI (zero for linear systems), jump-corrected (:meth:`_sample_points`)."""
        if system.is_linear:
            return jnp.zeros(self.size)
        s, q, qd, (_, _, weight, delta) = self._sample_points(x, velocity, system, p, layout)
        values = system.force(s, q, qd, p, "nonlinear", extra, jnp)
        N = self.samples
        projected = fourier.project(values[:, :N], self.harmonics, jnp) + _jumps(values[:, N:], weight) @ delta
        if events.declared(system, p):
            projected = projected + self._event_correction(x, velocity, extra, p, system)
        return projected.reshape(self.size)

    def _event_correction(self, x, velocity, extra, p, system):
        """The jumps of ``Q_nl`` at the zeros of the system's event functions
        (:func:`hbgear.engine.events.jump_correction`), shape ``(ndof, 2H+1)``."""
        n = self.ndof
        return events.jump_correction(system, p, extra, x.reshape(n, self.block), velocity.reshape(n, self.block),
                                      self.harmonics, self.nu, self.samples)

    def _sample_points(self, x, velocity, system, p, layout=None):
        r"""Where ``Q_nl`` is evaluated: the ``N`` uniform samples of the base period, then each
        candidate jump phase just after and just before it; returns ``(s, q, q', layout)``, the
        layout of :meth:`_jump_layout` (`layout`, when given: the quadrature's frozen one).

        ``Q_nl`` jumps where the load shares do (a pair enters or leaves contact, at known mesh
        phases): sampled uniformly, a jump aliases at ``O(1/N)``. With ``J_c`` the jump at base
        phase ``t_c`` (``Q_nl`` just after minus just before ``t_c``, at the state there), and the
        sawtooth ``B_c(t) = 1/2 - frac(t - t_c)`` (unit jump at ``t_c``, exact coefficients
        ``a_k = -sin(2 pi k t_c)/(pi k)``, ``b_k = cos(2 pi k t_c)/(pi k)``),

            P Q_nl  ~  P (Q_nl - sum_c J_c B_c) + sum_c J_c B_hat_c = P Q_nl + sum_c J_c (B_hat_c - P B_c)

        (``delta_c = B_hat_c - P B_c``): the sampled function left is continuous, so the
        projection errs at ``O(1/N^2)``. The candidates are phase 0 and the system's breakpoints
        (a phase listed twice counts once: ``weight``; where ``Q_nl`` is continuous ``J_c ~ 0``).
        A jump whose phase the state decides (a Coulomb law's ``V_s = 0``) stays ``O(1/N)``.
        """
        n, H, N, nu = self.ndof, self.harmonics, self.samples, self.nu
        layout = sides, at_c, _, _ = self._jump_layout(system, p) if layout is None else layout
        xc, vc = x.reshape(n, self.block), velocity.reshape(n, self.block)
        q_c, v_c = xc @ at_c.T, vc @ at_c.T  # (ndof, C): the state at the jump phases
        s = jnp.concatenate([jnp.mod(jnp.arange(N) * nu / N, 1.0), sides])
        q = jnp.concatenate([fourier.synthesize(xc, H, N, jnp), q_c, q_c], axis=1)
        qd = jnp.concatenate([fourier.synthesize(vc, H, N, jnp), v_c, v_c], axis=1)
        return s, q, qd, layout

    def _jump_layout(self, system, p):
        """``(sides, at_c, weight, delta)`` of :meth:`_sample_points`: the mesh phases just after
        and just before each candidate ``(2C,)``, the synthesis rows ``x(t_c) = x @ at_c.T``
        ``(C, 2H+1)``, ``1 / multiplicity`` ``(C,)`` and ``B_hat_c - P B_c`` ``(C, 2H+1)``.

        Built once in numpy when the breakpoints cannot depend on the parameter (the system
        declares ``coefficients_independent_of_parameter``), else in the trace.
        """
        if system.coefficients_independent_of_parameter and not _has_tracer(system):
            breakpoints = _breakpoint_key(system, 1.0)
            return _JUMPS.get_or_make((self, breakpoints), lambda: self._jump_layout_of(np.asarray(breakpoints), np))
        return self._jump_layout_of(jnp.ravel(jnp.asarray(system.breakpoints(p, jnp))), jnp)

    def _jump_layout_of(self, breakpoints, xp):
        H, N, nu = self.harmonics, self.samples, self.nu
        s_c, t_c, weight = events.breakpoint_instants(breakpoints, nu, xp)  # mesh phases, base fractions
        k = xp.arange(1, H + 1)
        angle = 2 * np.pi * t_c[:, None] * k[None]  # (C, H)

        def real_basis(cos, sin, mean):
            return xp.concatenate([mean, xp.stack([cos, sin], axis=-1).reshape(cos.shape[0], 2 * H)], axis=1)

        ones = xp.ones((t_c.shape[0], 1))
        at_c = real_basis(xp.cos(angle), xp.sin(angle), ones)
        eps = 1e-12
        sides = xp.concatenate([xp.mod(s_c + eps, 1.0), xp.mod(s_c - eps, 1.0)])
        exact = real_basis(-xp.sin(angle) / (np.pi * k), xp.cos(angle) / (np.pi * k), 0 * ones)
        sawtooth = 0.5 - xp.mod(xp.arange(N)[None] / N - t_c[:, None], 1.0)  # (C, N)
        return sides, at_c, weight, exact - fourier.project(sawtooth, H, xp)

    def _velocity(self, x, system, p):
        return fourier.differentiate(x.reshape(self.ndof, self.block), self.harmonics, self.base_frequency(system, p),
                                     jnp).reshape(self.size)

    def _residual(self, z, p, system, prepared, operator=None):
        x, extra = self._split(system, z)
        if operator is None:
            linear = self._linear_response(x, p, system, prepared)
        else:
            linear = operator[0] @ x - operator[1]
        r = linear - self._nonlinear(x, self._velocity(x, system, p), extra, p, system, prepared.jumps)
        k = system.free_mean_dof
        if k is not None:
            r = r.at[k * self.block].add(extra)
        return r / system.force_scale

    # -- public entry points: the prepared pieces are fetched outside the traced code ----------
    # (or given: `prepared` = self.prepare(system) computed once by a caller that traces
    # `system` itself, e.g. as an argument of a compiled continuation corrector)
    def residual(self, z, p, system, prepared=None):
        """Scaled residual ``R(z; p)``, shape ``(size,)``."""
        return self._residual_jit(z, p, system, self.prepare(system) if prepared is None else prepared)

    def residual_and_jacobian(self, z, p, system, prepared=None):
        """``(R, dR/dz)`` at fixed ``p`` (Newton): the affine part's Jacobian is its operator."""
        return self._residual_and_jacobian_jit(z, p, system, self.prepare(system) if prepared is None else prepared)

    def residual_and_jacobians(self, z, p, system, prepared=None):
        """``(R, dR/dz, dR/dp)`` (continuation)."""
        return self._residual_and_jacobians_jit(z, p, system,
                                                self.prepare(system) if prepared is None else prepared)

    def residual_and_linearization(self, z, p, system, prepared=None):
        """``(R, J)`` for Newton at fixed ``p``: ``J`` the dense ``dR/dz`` (the dense path, the same
        evaluation as :meth:`residual_and_jacobians`) or, on the structured path, a
        :class:`~hbgear.engine.structured.StructuredJacobian` (products and preconditioned GMRES
        solves, no matrix); which one, the prepared pieces say (:attr:`structured`)."""
        prepared = self.prepare(system) if prepared is None else prepared
        if prepared.structured is None:
            r, jac, _ = self._residual_and_jacobians_jit(z, p, system, prepared)
            return r, jac
        return structured.linearize(self, z, p, system, prepared)

    def hill_matrices(self, z, p, system, prepared=None):
        """``(J, D1, D2)`` of the Hill eigenproblem at a solution (mean unpinned), scaled.

        ``J = dR/dz``, ``D1 = 2 M (x) D + dR/d(velocity)``, ``D2 = M (x) I``.
        """
        return self._hill_matrices_jit(z, p, system, self.prepare(system) if prepared is None else prepared)

    @_kept_method
    def _residual_jit(self, z, p, system, prepared):
        return self._residual(z, p, system, prepared)

    def _nonlinear_jacobian(self, x, extra, p, system, layout=None):
        """``(T_q, T_v, I (x) D)``: ``d(P Q_nl)/dx = T_q + T_v (I (x) D)`` in SI, from the sampled
        pointwise derivatives of ``Q_nl`` with respect to ``q`` and ``q'``.

        ``P diag(g) E`` is the convolution matrix of the ``N``-point DFT coefficients of ``g``
        exactly when ``N > 4H`` (no index wraps), so the Jacobian costs ``2 ndof`` pointwise
        directional derivatives and FFTs instead of ``ndof (2H+1)`` tangents through the AFT;
        ``ndof`` when the system declares ``nonlinear_force_uses_displacement = False``
        (``T_q = 0``, e.g. friction that depends on the velocities only). The jump terms of
        :meth:`_sample_points` add ``delta_c^T dJ_c/dx(t_c) at_c`` from the same pointwise
        derivatives at the jump phases; the jumps at state-dependent zeros of event functions
        (:meth:`_event_correction`) add :func:`hbgear.engine.events.jump_jacobian`.
        """
        n, H, N = self.ndof, self.harmonics, self.samples
        uses_q = system.nonlinear_force_uses_displacement
        derivatives, (_, at_c, weight, delta) = self._nonlinear_derivatives(x, extra, p, system, layout)
        coeff = jnp.fft.rfft(derivatives[..., :N], axis=-1)[..., : 2 * H + 1] / N  # (1|2, n, n, 2H+1)
        blocks = fourier.convolution_matrix(coeff, H, jnp)  # (1|2, n, n, B, B)
        # the jump terms: J_c depends on the state at t_c only, x(t_c) = x @ at_c.T
        jumps = _jumps(derivatives[..., N:], weight)  # (1|2, n, n, C)
        blocks = blocks + jnp.einsum("cb,kijc,cd->kijbd", delta, jumps, at_c)
        t_q = self._flatten(blocks[0]) if uses_q else jnp.zeros((self.size, self.size))
        d = fourier.derivative_matrix(H, self.base_frequency(system, p), jnp)
        t_v = self._flatten(blocks[-1])
        if events.declared(system, p):  # the jumps at the event zeros move with the state
            velocity = self._velocity(x, system, p)
            e_q, e_v = events.jump_jacobian(system, p, extra, x.reshape(n, self.block), velocity.reshape(n, self.block),
                                            self.harmonics, self.nu, self.samples)
            t_q, t_v = t_q + self._flatten(e_q), t_v + self._flatten(e_v)
        return t_q, t_v, jnp.kron(jnp.eye(n), d)

    def _nonlinear_derivatives(self, x, extra, p, system, layout=None, directions=None):
        """``(G, layout)``: the pointwise derivatives of ``Q_nl`` at the sample points of
        :meth:`_sample_points` (``N`` uniform, then the ``2C`` jump sides), shape
        ``(1|2, n_row, n_col, N + 2C)`` (``dQ/dq`` first when the system uses it, then
        ``dQ/dq'``), from ``n`` directional derivatives each; `layout` the jump layout used.
        `directions` ``(n, k)``: derivatives along its columns instead (``n_col = k``)."""
        n = self.ndof
        s, q, qd, layout = self._sample_points(x, self._velocity(x, system, p), system, p, layout)

        def f(qq, vv):
            return system.force(s, qq, vv, p, "nonlinear", extra, jnp)

        eye = jnp.eye(n) if directions is None else directions

        def along_columns(g, at):
            """``(n_row, k, samples)``: the derivatives of `g` at `at` along the columns of `eye`,
            vmapped (the force traced and compiled once, not once per direction)."""
            tangent = lambda d: jax.jvp(g, (at,), (jnp.broadcast_to(d[:, None], at.shape),))[1]  # noqa: E731
            return jnp.moveaxis(jax.vmap(tangent)(eye.T), 0, 1)

        derivatives = [along_columns(lambda a: f(q, a), qd)]
        if system.nonlinear_force_uses_displacement:
            derivatives.insert(0, along_columns(lambda a: f(a, qd), q))
        return jnp.stack(derivatives), layout

    def _times_derivative(self, a, system, p, blocks=None):
        """``a @ (I (x) D)`` without the product: column ``a_k`` of each block becomes ``-k w`` times
        column ``b_k``, column ``b_k`` becomes ``k w`` times column ``a_k``, column ``a_0`` zero
        (`blocks`: the column blocks of `a`, default ``ndof``)."""
        blocks = self.ndof if blocks is None else blocks
        d = fourier.derivative_matrix(self.harmonics, 1.0)  # numpy: static structure
        source = np.argmax(np.abs(d), axis=0)  # the one nonzero row of each column of D
        factor = d[source, np.arange(self.block)]
        source = (np.arange(blocks)[:, None] * self.block + source[None]).ravel()
        factor = np.tile(factor, blocks) * self.base_frequency(system, p)
        return a[:, source] * factor

    def _toeplitz_ok(self, system) -> bool:
        """The sampled-derivative Jacobian is exact when ``N > 4H``."""
        return system.is_linear or self.samples > 4 * self.harmonics

    def _jacobian(self, z, p, system, prepared, operator):
        """``dR/dz`` (scaled) at the linear operator ``operator = (L, F, C)`` of ``p``."""
        if not self._toeplitz_ok(system):
            return jax.jacfwd(self._residual)(z, p, system, prepared, operator)
        jac = operator[0]
        if not system.is_linear:
            x, extra = self._split(system, z)
            t_q, t_v, _ = self._nonlinear_jacobian(x, extra, p, system, prepared.jumps)
            jac = jac - t_q - self._times_derivative(t_v, system, p)
        jac = jac * (system.displacement_scale / system.force_scale)
        k = system.free_mean_dof
        if k is not None:
            slot = k * self.block
            jac = jac.at[:, slot].set(0.0).at[slot, slot].add(1.0)
        return jac

    @_kept_method
    def _residual_and_jacobian_jit(self, z, p, system, prepared):
        operator = self.linear_operator(system, p, prepared)
        return self._residual(z, p, system, prepared, operator), self._jacobian(z, p, system, prepared, operator)

    @_kept_method
    def _residual_and_jacobians_jit(self, z, p, system, prepared):
        # R and dR/dp as ONE directional derivative in p (its primal is R; a joint jacfwd would
        # push all size+1 tangents through the operator's construction), dR/dz at a fixed operator
        r, jp = jax.jvp(lambda pp: self._residual(z, pp, system, prepared), (p,), (jnp.ones_like(p),))
        return r, self._jacobian(z, p, system, prepared, self.linear_operator(system, p, prepared)), jp

    def residual_and_port_jacobians(self, z, p, system, prepared):
        """``(R, dR/dz, dR/dp)`` on the condensed path: ``dR/dz`` as a
        :class:`~hbgear.engine.condensed.PortJacobian` (`prepared` must hold the condensed pieces)."""
        return self._residual_and_port_jacobians_jit(z, p, system, prepared)

    def residual_and_krylov_jacobians(self, z, p, system, prepared):
        """``(R, dR/dz, dR/dp)`` on the structured path: ``dR/dz`` as a
        :class:`~hbgear.engine.structured.KrylovJacobian` (products; the continuation corrector
        solves its bordered systems by GMRES). `prepared` must hold the structured pieces."""
        return self._residual_and_krylov_jacobians_jit(z, p, system, prepared)

    @_kept_method
    def _residual_and_krylov_jacobians_jit(self, z, p, system, prepared):
        r, jp = jax.jvp(lambda pp: self._residual(z, pp, system, prepared), (p,), (jnp.ones_like(p),))
        return r, structured.krylov_jacobian(self, z, p, system, prepared), jp

    @_kept_method
    def _residual_and_port_jacobians_jit(self, z, p, system, prepared):
        r, jp = jax.jvp(lambda pp: self._residual(z, pp, system, prepared), (p,), (jnp.ones_like(p),))
        return r, self._port_jacobian(z, p, system, prepared), jp

    def _port_operator(self, system, p, prepared):
        """``(Kb, Cb, P_K, P_C, c_K, c_C)`` of :class:`~hbgear.engine.condensed.CondensedOperator`: kept, or
        from the coefficients by quadrature (a parameter-dependent system)."""
        pieces = prepared.condensed
        if pieces.mean_stiffness is not None:
            return (pieces.mean_stiffness, pieces.mean_damping, pieces.stiffness_ports, pieces.damping_ports,
                    pieces.stiffness_coefficients, pieces.damping_coefficients)
        _, stiffness, damping = self._periodic_coefficients(system, p, prepared.rule)
        return condensed.port_operator(stiffness, damping, pieces.ports, pieces.outputs, self.harmonics, jnp)

    def _port_jacobian(self, z, p, system, prepared) -> condensed.PortJacobian:
        """``dR/dz = A + (O (x) I) U~ (C (x) I)`` (scaled) of :mod:`hbgear.engine.condensed`: ``A``
        from the mean periodic coefficients, ``U~ = (O^T (x) I)(dR/dx - A)(C^T (x) I)`` from the
        port parts of ``K(s)``, ``C(s)`` and ``m`` directional derivatives of ``Q_nl`` projected
        on the outputs ``O`` (``C`` orthonormal rows, ``O`` orthonormal columns)."""
        n, H, B = self.ndof, self.harmonics, self.block
        pieces = prepared.condensed
        w = self.base_frequency(system, p)
        scale = system.displacement_scale / system.force_scale
        k_bar, c_bar, k_ports, c_ports, c_k, c_c = self._port_operator(system, p, prepared)
        if system.is_linear:
            u = k_ports + w * c_ports
        else:
            x, extra = self._split(system, z)
            g_q, g_v, t_q, t_v, rest = self._nonlinear_port_parts(x, extra, p, system, prepared.jumps, pieces.ports.T,
                                                                  pieces.outputs, w)
            # A holds the mean derivatives of Q_nl too (a mesh that is all nonlinear, backlash,
            # leaves Kb no stiffness on its coordinate): the mean Jacobian
            k_bar, c_bar = k_bar - g_q @ pieces.ports, c_bar - g_v @ pieces.ports
            # U~ = P_K + w P_C - (T_q + w T_v D_1): the convolution parts gathered at once from
            # the coefficients' differences, the jump terms apart
            u = w * condensed.port_convolution(c_c - t_v, H, derivative=True) - rest
            if t_q is not None:
                u = u + condensed.port_convolution(c_k - t_q, H)
            else:
                u = u + k_ports
        u = u * scale
        mass = system.mass_matrix(p, jnp)
        kw = w * jnp.arange(1, H + 1)[:, None, None]
        diagonal = k_bar[None] - kw**2 * mass[None]
        coupling = kw * c_bar[None]
        blocks = jnp.concatenate([jnp.concatenate([diagonal, coupling], axis=2),
                                  jnp.concatenate([-coupling, diagonal], axis=2)], axis=1) * scale
        mean = k_bar * scale
        keep = jnp.ones(n * B)
        k = system.free_mean_dof
        if k is not None:
            mean = mean.at[:, k].set(0.0).at[k, k].set(1.0)
            keep = keep.at[k * B].set(0.0)
        return condensed.PortJacobian(mean, blocks, jnp.linalg.inv(mean), jnp.linalg.inv(blocks), u, pieces.ports,
                                      pieces.outputs, keep)

    def _nonlinear_port_parts(self, x, extra, p, system, layout, right, left, w):
        """``(Gb_q, Gb_v, c_q, c_v, J)``: :meth:`_nonlinear_jacobian`'s ``T_q + w T_v D_1`` between
        ``left (x) I`` and ``right (x) I`` (``r`` outputs, ``m`` ports) from ``m`` directional
        derivatives (the columns of `right` ``(n, m)``) projected on the rows of `left` ``(r, n)``:
        the means ``Gb`` ``(n, m)`` of the sampled derivatives (not projected: ``A`` holds all of
        them), the complex coefficients ``(r, m, B)`` of the rest (means zeroed) whose convolution
        matrices are ``T_q`` and ``T_v`` (``c_q`` ``None`` when ``Q_nl`` does not use ``q``), and ``J``
        ``(r B, m B)``: the jump terms ``delta_c^T J_c at_c`` (``at_c D_1`` for ``T_v``) and the
        event systems' moving jumps, as :func:`~hbgear.engine.condensed.port_matrix`."""
        n, H, N, B = self.ndof, self.harmonics, self.samples, self.block
        derivatives, (_, at_c, weight, delta) = self._nonlinear_derivatives(x, extra, p, system, layout, right)
        means = jnp.mean(derivatives[..., :N], axis=-1)  # (1|2, n, m)
        derivatives = jnp.einsum("ri,kijs->krjs", left, derivatives)
        coeff = jnp.fft.rfft(derivatives[..., :N], axis=-1)[..., :B] / N
        coeff = jnp.concatenate([0.0 * coeff[..., :1], coeff[..., 1:]], axis=-1)
        jumps = _jumps(derivatives[..., N:], weight)  # (1|2, r, m, C)
        r, m = left.shape[0], right.shape[1]
        uses_q = system.nonlinear_force_uses_displacement
        at_rows, jump_rows = w * condensed.times_d1(at_c, H, jnp), jumps[-1]
        if uses_q:
            at_rows = jnp.concatenate([at_c, at_rows], axis=0)
            jump_rows = jnp.concatenate([jumps[0], jump_rows], axis=-1)
            delta = jnp.concatenate([delta, delta], axis=0)
        # sum_c delta[c, b] J[i, j, c] at[c, d] at row b r + i, column d m + j
        rest = jnp.einsum("cb,ijc,cd->bidj", delta, jump_rows, at_rows).reshape(B * r, B * m)
        if events.declared(system, p):
            velocity = self._velocity(x, system, p)
            e_q, e_v = events.jump_jacobian(system, p, extra, x.reshape(n, self.block), velocity.reshape(n, self.block),
                                            self.harmonics, self.nu, self.samples)
            e_q = jnp.einsum("ri,ijbd,jl->rlbd", left, e_q, right)
            e_v = jnp.einsum("ri,ijbd,jl->rlbd", left, e_v, right)
            rest = rest + condensed.port_matrix(e_q + w * condensed.times_d1(e_v, H, jnp))
        g_q = means[0] if uses_q else jnp.zeros_like(means[0])
        return g_q, means[-1], (coeff[0] if uses_q else None), coeff[-1], rest

    @_kept_method
    def _hill_matrices_jit(self, z, p, system, prepared):
        x, extra = self._split(system, z)
        lin, _, c_conv = self.linear_operator(system, p, prepared)
        xs, fs = system.displacement_scale, system.force_scale

        if self._toeplitz_ok(system):
            # the same sampled-derivative blocks as the Newton Jacobian: d/dx = L - T_q - T_v D,
            # d/d(velocity) = C - T_v (no tangents through the AFT)
            if system.is_linear:
                jz, jv = lin / fs, c_conv / fs
            else:
                t_q, t_v, _ = self._nonlinear_jacobian(x, extra, p, system, prepared.jumps)
                jz, jv = (lin - t_q - self._times_derivative(t_v, system, p)) / fs, (c_conv - t_v) / fs
        else:

            def response(xx, shift):
                v = self._velocity(xx, system, p) + shift
                return (lin @ xx + c_conv @ shift - self._nonlinear(xx, v, extra, p, system, prepared.jumps)) / fs

            jz, jv = jax.jacfwd(response, argnums=(0, 1))(x, jnp.zeros_like(x))
        d = fourier.derivative_matrix(self.harmonics, self.base_frequency(system, p), jnp)
        mass = system.mass_matrix(p, jnp) / fs
        d2 = jnp.kron(mass, jnp.eye(self.block)) * xs
        d1 = (jv + 2 * jnp.kron(mass, d)) * xs
        return jz * xs, d1, d2


def residual_functions(hb: HarmonicBalance, system):
    """``(residual_and_jacobians, residual, args)`` in the form
    :func:`~hbgear.engine.continuation.continuation` takes: ``continuation(rj, r, ..., args=args)``.

    The two functions take ``(z, p, system, prepared)`` and are the same objects for every
    system solved with `hb`; ``args = (system, hb.prepare(system))``. The system's parameters are
    thus arguments of the compiled corrector, not constants in it: a new system with the
    same structure (e.g. a gear pair with the same ``H``, ``N``, laws, boundary) reuses the
    compiled program, in this process and from the disk cache.
    """
    return (*_functions_of(hb), (system, hb.prepare(system)))


@lru_cache(maxsize=16)
def _functions_of(hb: HarmonicBalance):
    def residual_and_jacobians(z, p, system, prepared):
        if prepared.condensed is not None:  # dR/dz as a PortJacobian (hbgear.engine.condensed)
            return hb.residual_and_port_jacobians(device_array(z), p, system, prepared)
        if prepared.structured is not None:  # as a KrylovJacobian (hbgear.engine.structured)
            return hb.residual_and_krylov_jacobians(device_array(z), p, system, prepared)
        return hb.residual_and_jacobians(device_array(z), p, system, prepared)

    def residual(z, p, system, prepared):
        return hb.residual(device_array(z), p, system, prepared)

    # what the compiled corrector asks before tracing (hbgear.engine.continuation.compiled); all
    # they close over is `hb` (frozen settings): programs traced from them may be kept on disk
    residual_and_jacobians.jacobian_is_structured = lambda system, prepared: jacobian_is_structured(prepared)
    residual_and_jacobians.program_key = residual.program_key = ("engine.hb._functions_of", hb)
    return residual_and_jacobians, residual


def jacobian_is_structured(prepared) -> bool:
    """Whether the continuation's ``dR/dz`` on these `prepared` pieces is an object (a
    :class:`~hbgear.engine.condensed.PortJacobian` or a :class:`~hbgear.engine.structured.KrylovJacobian`)
    rather than a matrix."""
    return prepared.condensed is not None or prepared.structured is not None


def _breakpoint_key(system, p) -> tuple:
    """The system's breakpoints at `p` as a hashable key (rounded to 1e-15: equal geometries
    share their cached rules and layouts)."""
    return tuple(np.round(np.ravel(np.asarray(system.breakpoints(p, np), dtype=float)), 15))


def _jumps(values, weight):
    """``(Q_nl(t_c+) - Q_nl(t_c-)) * weight`` from the values at the ``2C`` jump sides (last axis)."""
    count = weight.shape[0]
    return (values[..., :count] - values[..., count:]) * weight


def _has_tracer(tree) -> bool:
    return any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree_util.tree_leaves(tree))


#: Mesh-period rules per (breakpoints, R); frozen operators per (discretisation, system content);
#: jump layouts per (discretisation, breakpoints).
_RULES = BoundedCache(64)
_FROZEN = BoundedCache(64)
_JUMPS = BoundedCache(64)
