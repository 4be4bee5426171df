"""One periodic steady state of the gear pair by harmonic balance.

LTV models are linear: one exact solve of ``K_h(w) X = F(w)`` (the paper's Eq. 23).
Nonlinear models run a damped Newton iteration: without backlash first from the quasi-static
state (no LTV model to trace and compile: the NLTV friction is a mild nonlinearity away from the
pitch point, a few iterations suffice), then, or with backlash at once, from the LTV solution of
the same pair (with backlash the linear response picks the non-impacting state among coexisting
ones); if that fails for a steep friction law, the law's smoothing velocity is continued from a
gentle value down to the requested one. Non-convergence raises
:class:`~hbgear.errors.ConvergenceError` with the speed, what was tried and the residual.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from ..engine import fourier
from ..errors import ConvergenceError
from ..engine.hb import HarmonicBalance, _breakpoint_key
from ..engine.response import PeriodicSolution as EnginePeriodicSolution
from ..engine.response import newton_solve, synthesize
from .readouts import bearing_coefficients, periodic_summary, summary_keys
from .model import GearPairModel
from ..engine.quadrature import LatticeRule, lattice_rule, lattice_synthesis, mesh_period_rule
from .system import GearSystem

__all__ = ["PeriodicSolution", "solve_periodic", "start_guess", "read_outs", "auto_harmonics", "rpm_to_rad_s", "rad_s_to_rpm"]


def rpm_to_rad_s(rpm):
    return np.asarray(rpm) * (2 * np.pi / 60) if np.ndim(rpm) else float(rpm) * 2 * np.pi / 60


def rad_s_to_rpm(omega):
    return np.asarray(omega) * (60 / (2 * np.pi)) if np.ndim(omega) else float(omega) * 60 / (2 * np.pi)


@dataclass(frozen=True)
class PeriodicSolution(EnginePeriodicSolution):
    """A converged harmonic-balance solution of the gear pair (an engine
    :class:`~hbgear.engine.response.PeriodicSolution` of a :class:`~hbgear.gear.system.GearSystem`).

    **Fields** (besides the engine's `system`, `parameter`, `harmonics`, `nu`, `samples`, `z`,
    `residual_norm`, `iterations`, `multipliers`): `u_static_m`, the soft spring's static wind-up.

    **Derived:** `model`; `omega_pinion` [rad/s]; `speed_rpm`; `coefficients` [m], shape
    ``(ndof, 2H+1)`` (real basis of :mod:`hbgear.engine.fourier` on the base frequency ``w_m/nu``);
    `reaction_force_N` (``T_g/R_bg`` for the reaction boundary); :meth:`summary` (the INTERFACE
    read-outs), :meth:`harmonic_table`.
    """

    u_static_m: float = 0.0

    @property
    def model(self) -> GearPairModel:
        return self.system._at(self.parameter)[0]

    @property
    def omega_pinion(self) -> float:
        return float(self.system._at(self.parameter)[1])

    @property
    def reaction_force_N(self) -> float:
        return self.extra

    @property
    def speed_rpm(self) -> float:
        return rad_s_to_rpm(self.omega_pinion)

    def quadrature(self):
        """Nodes (base fractions, mesh phases) and weights over one base period."""
        base, s, w, _ = _read_out_rule(_breakpoint_key(GearSystem(self.model), self.omega_pinion), self.harmonics,
                                          self.nu)
        return base, s, w

    def summary(self) -> dict:
        """The INTERFACE read-outs (µm, W) from exact quadrature over the period; with the Floquet
        multipliers, also ``max_abs_floquet``."""
        out = _summaries(self.model, np.array([self.omega_pinion]), self.coefficients[None], self.harmonics, self.nu,
                         np.array([self.u_static_m]), np.array([self.reaction_force_N]), samples=self.samples)
        out = {k: float(v[0]) for k, v in out.items()}
        if self.multipliers is not None:
            m = np.asarray(self.multipliers)
            out["max_abs_floquet"] = float(np.max(np.abs(m))) if m.size else 0.0
        return out

    @classmethod
    def from_z(cls, model, omega_pinion, z, hb, *, residual_norm=0.0, iterations=0, multipliers=None) -> PeriodicSolution:
        """The solution of scaled unknowns `z` of the discretisation `hb` (reaction slot decoded)."""
        return cls(system=GearSystem(model), parameter=float(omega_pinion), harmonics=hb.harmonics, nu=hb.nu,
                   samples=hb.samples, z=np.asarray(z), residual_norm=float(residual_norm), iterations=int(iterations),
                   multipliers=multipliers, u_static_m=float(model.static_windup(omega_pinion)))

    def bearing_harmonic_table(self) -> tuple[list[str], list[list]]:
        """``harmonics.csv`` on bearings: the DTE columns of :meth:`harmonic_table` and, per bearing
        force, its amplitude [N] at each order (the mean at order 0). **Returns:** ``(header, rows)``."""
        header = ["mesh_order", "dte_amplitude_um", "dte_phase_deg"]
        rows = [list(r) for r in self.harmonic_table()]
        base = self.model.speeds(self.omega_pinion)[2] / self.nu
        for name, force in bearing_coefficients(self.model, self.coefficients[None], np.array([base])).items():
            mean, amp, _ = fourier.harmonic_amplitudes(force[0], self.harmonics)
            header.append(f"bearing_force_{name}_amplitude_N")
            for k, row in enumerate(rows):
                row.append(float(mean) if k == 0 else float(amp[k - 1]))
        return header, rows

    def harmonic_table(self):
        """Rows ``(order, amplitude_um, phase_deg)`` of the DTE; order in mesh orders (0.5 steps for nu=2)."""
        mean, amp, phase = fourier.harmonic_amplitudes(self.coefficients[0], self.harmonics)
        rows = [(0.0, 1e6 * float(mean), 0.0)]
        rows += [((k + 1) / self.nu, 1e6 * float(amp[k]), float(np.degrees(phase[k]))) for k in range(self.harmonics)]
        return rows


def _decode(model: GearPairModel, z, hb: HarmonicBalance):
    """Scaled unknowns ``z`` ``(..., size)`` -> coefficients [m] ``(..., ndof, 2H+1)`` and the
    reaction force ``T_g/R_bg`` [N] ``(...)`` (its slot, the mean of ``u``, is zeroed)."""
    return hb.decode(GearSystem(model), z)


_synthesize = synthesize


def _summaries(model, omegas, coefficients, harmonics, nu, u_static, reaction, keys=None,
               samples=None) -> dict:
    """:func:`~hbgear.gear.readouts.periodic_summary` of ``P`` solutions at once (exact quadrature over
    the period, the DTE peak-to-peak also on a dense grid): `coefficients` ``(P, ndof, 2H+1)``
    [m], `omegas`, `u_static`, `reaction` ``(P,)``; `keys` as there; `samples`: the solutions'
    AFT samples (where the friction loads jump at contact events, :func:`_event_split_summaries`).
    **Returns:** arrays ``(P,)``."""
    keys = summary_keys(model) if keys is None else tuple(keys)
    omega = np.asarray(omegas, dtype=float)[:, None]
    _, s, w, basis = _read_out_rule(_breakpoint_key(GearSystem(model), omega[0, 0]), harmonics, nu)
    base_frequency = model.speeds(omega)[2][:, :, None] / nu  # (P, 1, 1)
    q, qd = _node_states(coefficients, base_frequency, basis, nu)
    out = periodic_summary(model, omega, s[None], np.moveaxis(q, 1, 0), np.moveaxis(qd, 1, 0), w,
                           np.asarray(u_static, dtype=float)[:, None], np.asarray(reaction, dtype=float)[:, None],
                           keys=keys)
    if "dte_p2p_um" in out:  # the peak-to-peak between the nodes too: the DTE on 16 H uniform points (FFT)
        dense = fourier.synthesize(np.asarray(coefficients, dtype=float)[:, 0], harmonics, 16 * harmonics)
        out["dte_p2p_um"] = np.maximum(out["dte_p2p_um"], 1e6 * np.ptp(dense, axis=-1))
    for name, force in bearing_coefficients(model, coefficients, base_frequency[:, 0, 0]).items():  # likewise
        key = f"bearing_force_{name}_p2p_N"
        if key in out:
            out[key] = np.maximum(out[key], np.ptp(fourier.synthesize(force, harmonics, 16 * harmonics), axis=-1))
    if model.contact_events(np.zeros(1), np.zeros((model.ndof, 1)), 0.0) is not None:
        split = _event_split_summaries(model, omega[:, 0], coefficients, harmonics, nu, u_static, reaction, samples,
                                       keys)
        for key in keys:  # extremes: the larger of both rules; integrals: the split rule's
            out[key] = (np.maximum(out[key], split[key]) if key == "dynamic_factor" or key.endswith("_p2p_N")
                        else out[key] if key == "dte_p2p_um" else split[key])
    if "mean_mesh_power_W" in out:
        out["mean_mesh_power_W"] = out["mean_mesh_power_W"] - _impulse_power(model, omega[:, 0], coefficients,
                                                                             harmonics, nu)
    return out


def _event_split_summaries(model, omegas, coefficients, harmonics, nu, u_static, reaction, samples=None,
                           keys=None) -> dict:
    """The summaries point by point with the quadrature also split at the contact events.

    Where the friction loads jump at a flank's contact (:meth:`GearPairModel.contact_events`) the
    instants move with the solution: they are located as the harmonic balance does
    (:func:`hbgear.engine.events.crossings`) and added to the breakpoints of a base-period rule,
    so the read-outs integrate smooth pieces only. **Returns:** arrays ``(P,)``.
    """
    from ..engine.events import crossings_compiled

    keys = summary_keys(model) if keys is None else tuple(keys)
    system = GearSystem(model)
    samples = samples or max(1024, 4 * harmonics * nu + 2)
    phases = np.asarray(model.phase_breakpoints(), dtype=float)
    fixed = np.concatenate([(phases + j) / nu for j in range(nu)])
    rows = []
    coefficients = np.asarray(coefficients, dtype=float)
    located = None  # the compiled crossings, looked up once for the loop (every point's arguments alike)
    for omega, xc, u_s, r in zip(omegas, coefficients, u_static, reaction):
        base_frequency = float(model.speeds(float(omega))[2]) / nu
        vc = xc @ fourier.derivative_matrix(harmonics, base_frequency).T
        if located is None:
            located = crossings_compiled.for_arguments(system, float(omega), xc, vc, nu, samples)
        t, valid = (np.asarray(a) for a in located(system, float(omega), xc, vc, nu, samples))
        base, w = mesh_period_rule(np.concatenate([fixed, t[valid]]), 2 * harmonics + 8)
        tau = 2 * np.pi * np.outer(np.arange(1, harmonics + 1), base)
        q, qd = _synthesize(xc, base_frequency, np.cos(tau), np.sin(tau))
        rows.append(periodic_summary(model, float(omega), (base * nu) % 1.0, q, qd, w, float(u_s), float(r),
                                     keys=keys))
    return {key: np.array([float(row[key]) for row in rows]) for key in keys}


def _impulse_power(model, omegas, coefficients, harmonics, nu):
    """Mean power ``(1/(nu T_m)) sum_c [G]_c delta'(t_c)`` [W] of the LTI impulses ``[G]`` of
    ``-F_mesh`` at the stiffness jumps (:meth:`GearPairModel.lti_damping_impulse`), which the
    quadrature of ``<F_mesh delta'>`` between the jumps does not see; shape ``(P,)``, zero unless
    LTI. ``delta'(t_c)`` of the Fourier series is the mean of its two sides, as in time integration."""
    omegas = np.asarray(omegas, dtype=float)
    if model.coupling != "LTI":
        return np.zeros(omegas.shape)
    phases = np.asarray(model.phase_breakpoints(), dtype=float)
    impulse = np.array([model.lti_damping_impulse(s, 0.0)[0] for s in phases])  # on the DTE row
    base = np.concatenate([(phases + j) / nu for j in range(nu)])
    tau = 2 * np.pi * np.outer(np.arange(1, harmonics + 1), base)
    base_frequency = model.speeds(omegas)[2][:, None] / nu  # (P, 1)
    _, velocity = _synthesize(np.asarray(coefficients)[:, 0], base_frequency, np.cos(tau), np.sin(tau))
    return (velocity @ np.tile(impulse, nu)) * base_frequency[:, 0] / (2 * np.pi)


def _node_states(coefficients, base_frequency, basis, nu: int):
    """``(q, qd)`` at the read-out rule's nodes (:func:`_read_out_rule`), shapes ``(..., ndof, nodes)``:
    from the trigonometric basis ``(cos, sin)``, or by chirp transforms from a lattice rule (the
    nodes of base period ``j`` of ``nu`` at ``(j + s) / nu``)."""
    if not isinstance(basis, LatticeRule):
        return _synthesize(coefficients, base_frequency, *basis)
    c = np.asarray(coefficients, dtype=float)
    k = np.arange(c.shape[-1] // 2 + 1)
    position = np.concatenate([c[..., :1], c[..., 1::2] - 1j * c[..., 2::2]], axis=-1)  # x = Re sum c_k e^{i k tau}
    both = np.stack([position, 1j * k * position])  # one synthesis for q and q'
    states = np.concatenate([lattice_synthesis(both, basis, j / nu, 1.0 / nu) for j in range(nu)], axis=-1)
    return states[0], base_frequency * states[1]


#: Points per batch of :func:`read_outs`. The work arrays of a batch (the states at ~1900 nodes
#: of the example's curve: 4 MB at 128 points, 16 MB at 512) are fresh memory the first time, and
#: first touches are slow on the machines we measure on: the example's read-outs took 0.29-0.72 s
#: in batches of 512, 0.12-0.13 s in batches of 128 or 64 (same results to the bit).
READ_OUT_BATCH = 128


def read_outs(model: GearPairModel, omegas, zs, hb: HarmonicBalance, keys=None) -> dict:
    """``PeriodicSolution.from_z(model, w, z, hb).summary()`` for every point ``(omegas[i],
    zs[i])`` at once (a curve's read-outs): a dict of arrays ``(P,)`` keyed as the summary
    (`keys`: only those, see :func:`~hbgear.gear.readouts.periodic_summary`)."""
    omegas = np.asarray(omegas, dtype=float)
    coefficients, reaction = _decode(model, zs, hb)
    u_static = np.broadcast_to(np.asarray(model.static_windup(omegas), dtype=float), omegas.shape)
    parts = [_summaries(model, omegas[k:k + READ_OUT_BATCH], coefficients[k:k + READ_OUT_BATCH], hb.harmonics,
                        hb.nu, u_static[k:k + READ_OUT_BATCH], reaction[k:k + READ_OUT_BATCH], keys, hb.samples)
             for k in range(0, len(omegas), READ_OUT_BATCH)]
    return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}


#: From this many harmonics on the read-outs synthesise a solution at the quadrature nodes by
#: chirp transforms (:func:`~hbgear.engine.quadrature.lattice_synthesis`) instead of a
#: trigonometric basis of ``H x ~34 H / nu`` entries (36 MB at H = 256, 2.3 GB at H = 2048).
READ_OUT_LATTICE_HARMONICS = 128


@lru_cache(maxsize=32)
def _read_out_rule(breakpoints: tuple, harmonics: int, nu: int):
    """Quadrature over one base period for read-outs, with what synthesises a solution at its
    nodes (cached per geometry): ``(base, s, w, basis)``, `basis` the trigonometric basis
    ``(cos, sin)`` or, from :data:`READ_OUT_LATTICE_HARMONICS` on, the lattice rule."""
    order = 2 * harmonics // nu + 8
    lattice = lattice_rule(np.asarray(breakpoints), order, coefficients=False)
    s, w = lattice.nodes, lattice.weights  # those of mesh_period_rule(breakpoints, order)
    base = np.concatenate([(j + s) / nu for j in range(nu)])
    if harmonics >= READ_OUT_LATTICE_HARMONICS:
        return base, np.tile(s, nu), np.tile(w, nu) / nu, lattice
    tau = 2 * np.pi * np.outer(np.arange(1, harmonics + 1), base)
    return base, np.tile(s, nu), np.tile(w, nu) / nu, (np.cos(tau), np.sin(tau))


def _problem(model: GearPairModel, harmonics: int, nu: int, samples: int):
    hb = HarmonicBalance(model.ndof, harmonics, nu, samples)
    return hb, GearSystem(model)


def _newton(hb, system, omega, z0, tolerance, max_iterations):
    return newton_solve(hb, system, omega, z0, tolerance=tolerance, max_iterations=max_iterations)


def _steps(result) -> str:
    """How many Newton steps (and GMRES products, on the structured path) a result took."""
    krylov = f", {result.linear_iterations} GMRES products" if result.linear_iterations else ""
    return f"{result.iterations} iterations{krylov}"


_STATIC_START_ITERATIONS = 10


def _quasi_static_start(model: GearPairModel, hb: HarmonicBalance, system: GearSystem) -> np.ndarray:
    """Scaled unknowns of the quasi-static state: DTE mean ``N <1/k>`` (the mesh's mean static
    deflection) plus the STE mean (zero), harmonics zero; for the reaction boundary the output
    force unknown ``T_p / R_bp``."""
    z = np.zeros(hb.size)
    mean_compliance = float(model.mesh.mean_compliance(model))
    z[0] = float(model.normal_load_N) * mean_compliance / float(system.displacement_scale)
    if system.free_mean_dof is not None:
        z[system.free_mean_dof * hb.block] = 1.0  # T_g / R_bg ~ N, in units of force_scale = N
    return z


def start_guess(model: GearPairModel, hb: HarmonicBalance, system: GearSystem) -> np.ndarray | None:
    """A first guess for Newton at any speed, or ``None`` when only :func:`solve_periodic`'s
    staged start will do: zeros for a linear model (Newton solves it in one step), the
    quasi-static state for a non-linear model with linear contact (:func:`_quasi_static_start`,
    where :func:`solve_periodic` starts too), ``None`` with backlash."""
    if model.is_linear:
        return np.zeros(hb.size)
    if model.contact == "linear":
        return _quasi_static_start(model, hb, system)
    return None


def _smoothing_field(model: GearPairModel):
    law = model.friction
    for name in ("v0", "v_reg"):
        if hasattr(law, name) and getattr(law, name) > 0:
            return name
    return None


def solve_periodic(
    model: GearPairModel,
    omega_pinion: float,
    *,
    harmonics: int = 24,
    nu: int = 1,
    samples: int | None = None,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
    z0: np.ndarray | None = None,
) -> PeriodicSolution:
    """The periodic steady state at pinion speed `omega_pinion` [rad/s].

    **Raises:** :class:`ConvergenceError` when Newton (and the smoothing continuation for
    steep friction laws) does not reach `tolerance`.
    """
    samples = samples or max(1024, 4 * harmonics * nu + 2)
    samples += samples % nu
    hb, system = _problem(model, harmonics, nu, samples)
    omega = float(omega_pinion)
    tried = []
    guess = start_guess(model, hb, system) if z0 is None else None
    if model.is_linear:
        z = guess if z0 is None else np.asarray(z0)
        result = _newton(hb, system, omega, z, tolerance, 3)
        tried.append("direct linear solve" + (f" ({result.linear_iterations} GMRES products)"
                                              if result.linear_iterations else ""))
    else:
        result = None
        if guess is not None:
            z0 = guess
            result = _newton(hb, system, omega, z0, tolerance, min(max_iterations, _STATIC_START_ITERATIONS))
            tried.append(f"Newton from the quasi-static state ({_steps(result)})")
            z0 = z0 if result.converged else None
        if result is None or not result.converged:
            start_name = "given"
            if z0 is None:
                linear = (model.replace(coupling="LTV", contact="linear", normal_loads="signed",
                                        mesh=model.mesh.closed()) if model.coupling != "LTI" else model)
                start = solve_periodic(linear, omega, harmonics=harmonics, nu=nu, samples=samples, tolerance=tolerance)
                z0 = np.array(start.z)
                if model.contact == "backlash":  # the loaded teeth sit half the backlash further on
                    z0[0] += 0.5 * float(model.backlash_m) / float(system.displacement_scale)
                start_name = "LTV"
            result = _newton(hb, system, omega, z0, tolerance, max_iterations)
            tried.append(f"Newton from the {start_name} start ({_steps(result)})")
        name = _smoothing_field(model)
        if not result.converged and name is not None:
            target = getattr(model.friction, name)
            z = np.asarray(z0)
            for v in np.geomspace(max(0.5, 50 * target), target, 12):
                stage = model.replace(friction=replace(model.friction, **{name: float(v)}))
                result = _newton(hb, GearSystem(stage), omega, z, tolerance, max_iterations)
                if not result.converged:
                    break
                z = result.z
            tried.append(f"continuation of the friction smoothing {name} down to {target:g} m/s")
    if not result.converged:
        raise ConvergenceError(
            f"harmonic balance at {rad_s_to_rpm(omega):.6g} rpm (H={harmonics}, nu={nu}, N={samples}): "
            f"tried {'; '.join(tried)}; residual {result.residual_norm:.3e} (relative to the static load) "
            f"> tolerance {tolerance:.1e}"
        )
    return PeriodicSolution.from_z(model, omega, result.z, hb, residual_norm=result.residual_norm, iterations=result.iterations)


def auto_harmonics(
    model: GearPairModel,
    omega_pinion: float,
    *,
    nu: int = 1,
    tail_share: float = 1e-3,
    max_harmonics: int = 512,
    tolerance: float = 1e-9,
    max_iterations: int = 50,
) -> PeriodicSolution:
    """Solve with ``H`` grown until the top quarter of the harmonics is negligible.

    Starts above the mesh mode (``H >= 2 w_n / w``, ``w_n = sqrt(k_mean/m_e)``, since the mode
    rings once per ``w / w_n`` of the base period at low speed) and doubles ``H`` until the RMS of
    the DTE harmonics above ``3H/4`` is below `tail_share` of the DTE RMS. The ``H`` used is the
    solution's ``harmonics``.

    **Raises:** :class:`ConvergenceError` if ``max_harmonics`` is reached first.
    """
    omega_n = float((model.k_mean_N_per_m / model.mass_equivalent_kg) ** 0.5)
    base = float(model.speeds(omega_pinion)[2]) / nu
    harmonics = int(min(max_harmonics, max(16, 8 * int(np.ceil(2 * omega_n / base / 8)))))
    z0 = None
    while True:
        solution = solve_periodic(
            model, omega_pinion, harmonics=harmonics, nu=nu, tolerance=tolerance, max_iterations=max_iterations, z0=z0
        )
        _, amp, _ = fourier.harmonic_amplitudes(solution.coefficients[0], harmonics)
        total = float(np.sqrt(np.sum(amp**2)))
        tail = float(np.sqrt(np.sum(amp[(3 * harmonics) // 4 :] ** 2)))
        if total == 0.0 or tail <= tail_share * total:
            return solution
        if harmonics >= max_harmonics:
            raise ConvergenceError(
                f"harmonics = 'auto' at {rad_s_to_rpm(omega_pinion):.6g} rpm: the top quarter still carries "
                f"{tail / total:.2e} of the DTE at H = {harmonics} (limit {max_harmonics}); set solver.harmonics"
            )
        previous = solution.z.reshape(model.ndof, -1)
        harmonics = min(max_harmonics, 2 * harmonics)
        z0 = np.zeros((model.ndof, 2 * harmonics + 1))
        z0[:, : previous.shape[1]] = previous
        z0 = z0.ravel()
