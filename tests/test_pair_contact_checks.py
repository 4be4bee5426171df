"""Per-pair tooth contact (MODEL.md section 9): HB against time integration and the energy identity
with relief and contact loss (harmonic balance and time integration), the order of convergence in H
with the ISO stiffness, and the half-order (``nu = 2``) harmonic balance on a relieved pair.

The energy identity is evaluated here by a second route: the pair forces, the relief, the ISO
parabola, the static load sharing and the friction are written out below from MODEL.md's formulas
(only the numbers -- ISO's ``c'``, ``c_gamma_alpha``, the relief amounts and lengths, the geometry --
are read from the model's objects), and the powers are integrated by a Gauss rule split at the
breakpoints and at the contact events located on the solution itself."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from pair_contact_models import iso_relief_model

from hbgear.gear.solve import solve_periodic

GAUSS_NODES = 48  # per sub-interval; the sub-intervals are at most 1/64 of a mesh period


class HandMesh:
    """MODEL.md section 9 written out for the ISO parabola with linear tip relief on both gears
    (no backlash, no unloaded STE), drive flank; formulation A's quasi-static loads by the two-pair
    closed form; LTV Coulomb friction on the nominal sliding velocity."""

    def __init__(self, model, contact):
        g = contact.geometry
        self.xa, self.xe, self.pb, self.L = g.contact_start_m, g.contact_end_m, g.base_pitch_m, g.line_of_action_m
        self.gamma = (self.xe - self.xa) / self.pb
        self.rbp, self.rbg = g.base_radius_pinion_m, g.base_radius_gear_m
        b_mm = float(model.face_width_m) * 1e3
        self.k_peak = contact.iso6336.c_prime_N_per_mm_um * b_mm * 1e6
        self.k_mean = contact.iso6336.c_gamma_alpha_N_per_mm_um * b_mm * 1e6
        self.curvature = 0.75 * (self.gamma - 1.0) / self.gamma  # max c' b, mesh mean c_gamma_alpha b
        mod = contact.modification
        self.relief = (mod.pinion.tip_relief_m, mod.pinion.tip_length_m, mod.gear.tip_relief_m, mod.gear.tip_length_m)
        assert mod.pinion.root_relief_m == 0.0 and mod.gear.root_relief_m == 0.0 and mod.pinion.shape == "linear"
        me = 1.0 / (self.rbp**2 / float(model.inertia_pinion_kgm2) + self.rbg**2 / float(model.inertia_gear_kgm2))
        self.c = 2.0 * float(model.damping_ratio) * math.sqrt(self.k_mean * me)
        self.load = float(model.torque_pinion_Nm) / self.rbp
        self.teeth = (int(model.teeth_pinion), int(model.teeth_gear))
        self.mu0 = float(model.friction.mu0)
        self.pitch_age = (g.pitch_point_m - self.xa) / self.pb

    def slots(self, s):
        """``(xi_p, in_path, k_j, e_j, de_j/dxi)`` of the two slots at phases `s`, shape ``(2, n)``."""
        age = np.asarray(s)[None] + np.arange(2.0)[:, None]
        xi = self.xa + self.pb * age
        inside = age < self.gamma
        u = (xi - self.xa) / (self.xe - self.xa)
        k = np.where(inside, self.k_peak * (1.0 - self.curvature * (2.0 * u - 1.0) ** 2), 0.0)
        cp, lp, cg, lg = self.relief
        e = cp * np.maximum(xi - (self.xe - lp), 0.0) / lp + cg * np.maximum(self.xa + lg - xi, 0.0) / lg
        de = cp / lp * (xi > self.xe - lp) - cg / lg * (xi < self.xa + lg)
        return xi, inside, k, e, de

    def breakpoints(self):
        """Entry, exit, pitch crossing and relief starts, as mesh phases."""
        _, lp, _, lg = self.relief
        ages = [0.0, self.gamma - 1.0, self.pitch_age, lg / self.pb, self.gamma - lp / self.pb]
        return sorted({round(a % 1.0, 14) for a in ages})

    def closures(self, s, x):
        """``x - e_j`` of the slots in the path (``+inf`` outside, where no pair is)."""
        _, inside, _, e, _ = self.slots(s)
        return np.where(inside, x[None] - e, np.inf)

    def static_loads(self, s):
        """Quasi-static pair loads at ``N``: both pairs loaded if the common deflection exceeds both
        reliefs, else the pair with the smaller relief alone."""
        _, inside, k, e, _ = self.slots(s)
        both = (self.load + np.sum(k * e, axis=0)) / np.maximum(np.sum(k, axis=0), 1.0)
        two = inside.all(axis=0) & (both > e.max(axis=0))
        first = np.where(inside[1] & (e[1] < e[0]), 1, 0)
        alone = np.take_along_axis(e, first[None], 0)[0] + self.load / np.take_along_axis(k, first[None], 0)[0]
        deflection = np.where(two, both, alone)
        return np.where(inside, k * np.maximum(deflection[None] - e, 0.0), 0.0)

    def powers(self, s, q, qd, w, omega, formulation, spring):
        """Mean input - output power, friction loss and ``<F_mesh delta'>`` [W]; `spring`:
        ``(k_b, c_b, u_static)`` of the output spring."""
        _, inside, k, e, de = self.slots(s)
        xi = self.xa + self.pb * (s[None] + np.arange(2.0)[:, None])
        omega_g = omega * self.teeth[0] / self.teeth[1]
        x, xd, ud = q[0], qd[0], qd[1]
        drive = inside & (x[None] - e > 0.0)
        rate = de * self.rbp * omega  # de_j/dt
        force = np.where(drive, k * (x[None] - e) + self.c * k / self.k_mean * (xd[None] - rate), 0.0)
        assert np.all(~inside | (x[None] > 0.0))  # no back-flank contact on this solution
        mesh = np.sum(force, axis=0)
        wp, wg = omega + (xd + ud) / self.rbp, omega_g + ud / self.rbg
        normal = self.static_loads(s) * drive if formulation == "A" else np.maximum(force, 0.0)
        mu = self.mu0 * np.sign(xi * omega - (self.L - xi) * omega_g)
        t_p, t_g = -np.sum(mu * normal * xi, axis=0), np.sum(mu * normal * (self.L - xi), axis=0)
        kb, cb, u_static = spring
        t_out = self.rbg * (kb * (q[1] + u_static) + cb * ud)
        net = np.sum(w * (float(self.load * self.rbp) * wp - t_out * wg))
        return net, -np.sum(w * (t_p * wp + t_g * wg)), np.sum(w * mesh * xd)


def event_rule(hand, state, nodes=GAUSS_NODES, grid=4096):
    """Gauss rule over the mesh period split at the breakpoints, at every 1/64 and at the zeros of
    the pair closures ``x - e_j`` of ``state(s) -> (q, qd)`` (located by Brent's method)."""
    cuts = set(hand.breakpoints()) | set(np.arange(64) / 64)
    f = np.arange(grid + 1) / grid
    h = hand.closures(f, state(f)[0][0])
    for j in range(2):
        flip = np.nonzero(np.isfinite(h[j, :-1]) & np.isfinite(h[j, 1:]) & (np.sign(h[j, :-1]) != np.sign(h[j, 1:])))[0]
        for i in flip:
            def closure(p, j=j):
                return hand.closures(np.array([p]), state(np.array([p]))[0][0])[j, 0]

            cuts.add(brentq(closure, f[i], f[i + 1], xtol=1e-15))
    edges = np.array(sorted(cuts) + [1.0])
    t, wt = np.polynomial.legendre.leggauss(nodes)
    a, b = edges[:-1, None], edges[1:, None]
    return (0.5 * (a + b) + 0.5 * (b - a) * t).ravel(), (0.5 * (b - a) * wt).ravel(), len(cuts)


# ------------------------------------------------------------------ the energy identity
RPM_LOSS = 6000.0  # the relief for 226 N m run at 100 N m: the relieved tips open (partial contact loss)


@pytest.fixture(scope="module")
def relieved_run():
    """The relieved ISO pair at 100 N m and 6000 rpm (spring boundary, LTV Coulomb A): the model, its
    hand-written mesh, harmonic balance (H = 32) and time integration."""
    from hbgear.gear.simulate import simulate

    model, contact = iso_relief_model(100.0)
    omega = RPM_LOSS * math.pi / 30
    return model, HandMesh(model, contact), omega, solve_periodic(model, omega, harmonics=32), simulate(
        model, omega, period_cycles=(1,))


def test_hb_matches_time_integration_with_partial_contact_loss(relieved_run):
    """Relief for 226 N m run at 100 N m: the relieved tips open (pairs carry nothing over part of
    the double-contact zone, and near the resonance the contact of each pair opens and closes with
    the vibration: the dampers' jumps are events). HB (H = 64) against time integration (the
    module's run): 0.1 %."""
    model, _, omega, _, ti = relieved_run
    hb = solve_periodic(model, omega, harmonics=64)
    hs, ts = hb.summary(), ti.summary
    f = np.linspace(0.0, 1.0, 1024, endpoint=False)
    q = np.asarray(hb.state_at(f)[0])
    open_fraction = np.mean(np.asarray(model.pair_contact(f, q, 0.0 * q, omega).drive).sum(axis=0)
                            < np.asarray(model.pair_positions(f)[2]).sum(axis=0))
    assert open_fraction > 0.05  # partial contact loss: some pair of the path open
    for key in ("dte_mean_um", "dte_rms_um", "dte_p2p_um"):
        assert ts[key] == pytest.approx(hs[key], rel=1e-3), key


def _balance(hand, model, omega, s, q, qd, w, u_static):
    net, friction, mesh = hand.powers(s, q, qd, w, omega, model.formulation, (
        float(model.spring_stiffness_N_per_m), float(model.spring_damping_Ns_per_m), u_static))
    dissipation = friction + hand.c * np.sum(w * qd[0] ** 2)
    return (net - friction - mesh) / dissipation, friction


def test_hand_written_mesh_is_the_model_mesh(relieved_run):
    """The second route's force law is MODEL.md section 9's: the hand-written F_mesh equals the
    model's along the HB solution (a guard on the route, not evidence)."""
    model, hand, omega, sol, _ = relieved_run
    s = np.linspace(0.0, 1.0, 997, endpoint=False)
    q, qd = (np.asarray(a) for a in sol.state_at(s))
    _, inside, k, e, de = hand.slots(s)
    drive = inside & (q[0][None] - e > 0.0)
    force = np.where(drive, k * (q[0][None] - e) + hand.c * k / hand.k_mean * (qd[0][None] - de * hand.rbp * omega), 0.0)
    mine = np.asarray(model.mesh_force(s, q, qd, omega))
    assert np.max(np.abs(force.sum(axis=0) - mine)) < 1e-9 * np.max(np.abs(mine))
    assert 0.05 < np.mean(~drive & inside) < 0.5  # pairs of the path open for part of the period


def test_energy_identity_from_time_integration(relieved_run):
    """Net input power = friction loss + <F_mesh delta'> along the time integration, with the
    hand-written forces and friction at the integrator's quadrature nodes: measured 2.7e-7 of the
    dissipation (rtol 1e-9; the integrator's nodes are a fixed rule between the breakpoints, not
    split at the contact events)."""
    model, hand, omega, _, ti = relieved_run
    s, q, qd, w = ti.nodes
    imbalance, friction = _balance(hand, model, omega, s, q, qd, w, ti.u_static)
    assert friction > 500.0  # ~730 W: friction matters here
    assert abs(imbalance) < 1e-6, imbalance


def test_energy_identity_from_harmonic_balance(relieved_run):
    """The same identity along the HB solution (H = 32, N = 1024), integrated by Gauss between the
    breakpoints and the located contact events: measured 5.2e-7 of the dissipation, the AFT's
    error at the kinks of the relieved contact (7.8e-7 and 9.7e-6 at N = 1024 and 256 with H = 16,
    about O(1/N^2)); the read-outs' own balance (:meth:`PeriodicSolution.summary`) 8.4e-7 (it was
    1.8e-5 while the wind-up's two quadratures differed, below)."""
    model, hand, omega, sol, _ = relieved_run
    s, w, _ = event_rule(hand, sol.state_at)
    q, qd = (np.asarray(a) for a in sol.state_at(s))
    imbalance, friction = _balance(hand, model, omega, s, q, qd, w, sol.u_static_m)
    assert abs(imbalance) < 1e-6, imbalance
    summary = sol.summary()
    assert summary["mean_friction_loss_W"] == pytest.approx(friction, rel=1e-6)
    assert abs(summary["mean_power_loss_W"] - summary["mean_friction_loss_W"] - summary["mean_mesh_power_W"]) < (
        1e-6 * friction)


def test_spring_windup_is_one_number_in_numpy_and_compiled(relieved_run):
    """The soft spring's static wind-up ``u_s`` enters the compiled HB residual (jax.numpy) and the
    read-outs and time integration (numpy); the HB mean of ``u`` absorbs whichever ``u_s`` it is
    given, but the output power ``k_b (u + u_s) Omega_g R_bg`` does not. With relief the
    quasi-static pair loads have a kink between the breakpoints (a relieved pair taking up load),
    where two quadrature layouts differ beyond rounding: they did by 7.9e-7 m of 3.96 m here, which
    made the summary's energy balance miss by 1.8e-5 of the dissipation (exactly
    ``k_b du_s Omega_g R_bg``). The same nodes in both now: 1.3e-15 relative."""
    import jax
    import jax.numpy as jnp

    model, _, omega, _, _ = relieved_run
    compiled = float(jax.jit(lambda m: m.static_windup(omega, jnp))(model))
    numpy = float(model.static_windup(omega))
    assert numpy == pytest.approx(compiled, rel=1e-13)
    power = float(model.spring_stiffness_N_per_m) * abs(numpy - compiled) * omega * 25 / 31 * float(model.base_radius_gear_m)
    assert power < 1e-9  # W, against ~730 W of friction loss


# ------------------------------------------------------------------ half orders (nu = 2)
def test_half_order_balance_on_a_relieved_pair_returns_the_mesh_periodic_solution(relieved_run):
    """``nu = 2`` (base frequency ``w_m/2``, H = 64) on the relieved pair with partial contact loss,
    started from the ``nu = 1`` solution (H = 32; the one time integration settles on) with its half
    orders disturbed by 10 % of its largest amplitude: Newton removes them and the even harmonics
    are the ``nu = 1`` solution (the same AFT density, 2048 samples over two mesh periods).
    Newton to 1e-12 here (at the default 1e-9 the half orders stopped at 2.0e-10 of the largest
    amplitude with the earlier contact events, 1.5e-8 with the slope-corrected ones: the
    tolerance, not the physics, sets that level)."""
    model, _, omega, sol, ti = relieved_run
    # the mesh-periodic solution is the one time integration settles on from the static state
    assert ti.period_cycles == 1 and ti.summary["dte_p2p_um"] == pytest.approx(sol.summary()["dte_p2p_um"], rel=1e-3)
    h1 = sol.harmonics
    n = model.ndof
    one = np.asarray(sol.z).reshape(n, 2 * h1 + 1)
    two = np.zeros((n, 4 * h1 + 1))
    two[:, 0] = one[:, 0]
    two[:, 3::4], two[:, 4::4] = one[:, 1::2], one[:, 2::2]  # mesh order k = base harmonic 2k
    rng = np.random.default_rng(7)
    odd = np.zeros_like(two, dtype=bool)
    odd[:, 1::4] = odd[:, 2::4] = True  # base harmonics 1, 3, 5, ...: the half orders
    two[odd] += 0.1 * np.max(np.abs(one[:, 1:]), axis=1, keepdims=True).repeat(odd.shape[1], 1)[odd] * rng.standard_normal(odd.sum())
    half = solve_periodic(model, omega, harmonics=2 * h1, nu=2, samples=2 * sol.samples, z0=two.ravel(), tolerance=1e-12)
    c1, c2 = np.asarray(sol.coefficients), np.asarray(half.coefficients)
    scale = np.max(np.abs(c1[:, 1:]), axis=1)
    assert np.max(np.abs(c2[:, 1::4]) + np.abs(c2[:, 2::4]), axis=1) == pytest.approx(0.0 * scale, abs=1e-9 * scale.max())
    assert np.max(np.abs(c2[:, 3::4] - c1[:, 1::2]) + np.abs(c2[:, 4::4] - c1[:, 2::2])) < 1e-8 * scale.max()
    # the means: the DTE's to 1e-8, the soft spring's u through its mean force k_b <u> (N/k_b ~ 9 m)
    assert abs(c2[0, 0] - c1[0, 0]) < 1e-8 * abs(c1[0, 0])
    assert float(model.spring_stiffness_N_per_m) * abs(c2[1, 0] - c1[1, 0]) < 1e-8 * float(model.normal_load_N)
    assert half.summary()["dte_p2p_um"] == pytest.approx(sol.summary()["dte_p2p_um"], rel=1e-8)


# ------------------------------------------------------------------ convergence in H
def _slope(x, y):
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def test_observed_order_of_convergence_in_h_with_the_iso_stiffness():
    """The unrelieved ISO pair (a linear model: every pair of the path stays loaded), LTV Coulomb A,
    torques, 7000 rpm, against H = 256. Expected orders from the smoothness of the coefficients:
    ``k(t) = sum_j k_pair(xi_j)`` is a parabola per pair, smooth between pair entry and exit where it
    jumps (the ISO parabola ends at 0.773 ``c' b``, not 0), ``c(t)`` with it; the friction force
    jumps at the pitch point. So ``m_e delta''`` jumps, ``delta`` and ``delta'`` are continuous:
    the DTE coefficients decay like ``n^-3``, the truncated waveform errs like
    ``sqrt(sum_{n>H} n^-6) ~ H^-2.5`` in RMS and ``sum_{n>H} n^-3 ~ H^-2`` at its worst point.
    Measured over H = 16, 32, 64: decay -2.94 (orders 16..128), RMS error -2.50, max error -1.99
    (the rectangular pulse's in tests/test_hb.py: -3.04, -2.51, -1.99); RMS error at H = 64 1.1e-5
    of the DTE's standard deviation."""
    from hbgear.engine import fourier

    model, _ = iso_relief_model(226.0, relief=False, boundary="torques")
    assert model.is_linear
    omega = 7000.0 * math.pi / 30
    grid = np.linspace(0, 1, 8192, endpoint=False)
    reference = solve_periodic(model, omega, harmonics=256)
    dte = np.asarray(reference.state_at(grid)[0][0])
    _, amp, _ = fourier.harmonic_amplitudes(np.asarray(reference.coefficients[0]), 256)
    orders = np.arange(1, 257)
    tail = (orders >= 16) & (orders <= 128)
    harmonics = np.array([16, 32, 64])
    rms_error, max_error = [], []
    for h in harmonics:
        error = np.asarray(solve_periodic(model, omega, harmonics=int(h)).state_at(grid)[0][0]) - dte
        rms_error.append(np.sqrt(np.mean(error**2)))
        max_error.append(np.max(np.abs(error)))
    assert _slope(orders[tail], amp[tail]) == pytest.approx(-3.0, abs=0.2)
    assert _slope(harmonics, rms_error) == pytest.approx(-2.5, abs=0.2)
    assert _slope(harmonics, max_error) == pytest.approx(-2.0, abs=0.2)
    assert rms_error[-1] < 3e-5 * np.std(dte)
