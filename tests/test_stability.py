"""hbgear.engine.floquet and `hbgear stability-map`: Hill = exact monodromy, parametric tongues,
distributed = local, resume without recomputation."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import linear_sum_assignment

from hbgear.engine import floquet

from hbgear.build import model_at_contact_ratio
from hbgear.gear import maps

from hbgear.gear import monodromy
from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine.hb import HarmonicBalance
from hbgear.gear.system import GearSystem

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
RPM = 60.0 / (2.0 * np.pi)


def config(*overrides):
    return load_config(EXAMPLE, list(overrides))


def model(boundary="torques", zeta=0.01, formulation="A"):
    return build_model(
        config(f'boundary.output="{boundary}"', f"mesh.damping_ratio={zeta}", f'friction.formulation="{formulation}"')
    )


def natural_frequency(m):
    return math.sqrt(m.k_mean_N_per_m / m.mass_equivalent_kg)


def tongue_rpm(m, j):
    """Pinion speed of the j-th parametric tongue, w_m = 2 w_n / j."""
    return 2.0 * natural_frequency(m) / j / m.teeth_pinion * RPM


def max_pair_distance(a, b):
    assert len(a) == len(b), (a, b)
    d = np.abs(np.asarray(a)[:, None] - np.asarray(b)[None, :])
    rows, cols = linear_sum_assignment(d)
    return d[rows, cols].max()


# ----------------------------------------------------------------------------- Hill = monodromy


@pytest.mark.parametrize(
    "boundary, where",
    [("torques", "tongue"), ("torques", "stable"), ("spring", "tongue"), ("reaction", "stable")],
)
def test_hill_multipliers_equal_exact_monodromy_ltv_a(boundary, where):
    m = model(boundary)
    rpm = tongue_rpm(m, 1) if where == "tongue" else 20000.0
    omega = rpm / RPM
    exact = monodromy.multipliers_linear(m, omega)
    hb = HarmonicBalance(m.ndof, 32, 1, 132)
    hill = floquet.hill_multipliers(hb, np.zeros(hb.size), omega, GearSystem(m))  # linear: J independent of z
    assert len(exact) == len(hill) == 2 * m.ndof - (2 if boundary == "reaction" else 0)
    assert max_pair_distance(hill, exact) < 1e-6
    assert floquet.is_stable(exact) == (where == "stable")


def test_monodromy_ltv_a_is_product_of_expm_and_rejects_other_models():
    m = model("torques")
    omega = 15000.0 / RPM
    tm = 2 * np.pi / (m.teeth_pinion * omega)
    edges = np.append(m.phase_breakpoints(), 1.0)
    phi = np.eye(2)
    for a, b in zip(edges[:-1], edges[1:]):
        k = float(m.mesh_stiffness(0.5 * (a + b)))
        c = float(m.mesh_damping_Ns_per_m)
        me = float(m.mass_equivalent_kg)
        phi = expm(np.array([[0, 1], [-k / me, -c / me]]) * (b - a) * tm) @ phi
    np.testing.assert_allclose(monodromy.monodromy_ltv_a(m, omega), phi, rtol=1e-11, atol=1e-13 * np.abs(phi).max())
    with pytest.raises(ValueError, match="formulation"):
        monodromy.monodromy_ltv_a(model("torques", formulation="B"), omega)


def test_expm_batched_matches_scipy():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(50, 4, 4)) * np.logspace(-3, 2, 50)[:, None, None]
    ref = np.stack([expm(x) for x in a])
    np.testing.assert_allclose(monodromy.expm_batched(a), ref, rtol=1e-11, atol=1e-12 * np.abs(ref).max())


def test_formulation_b_magnus_equals_variational_equations():
    # the signed loads sigma_j F_mesh: LTV-B's linear equivalent along states with F_mesh > 0
    m = model("torques", formulation="B").replace(normal_loads="signed")
    omega = 26000.0 / RPM
    magnus = monodromy.monodromy_linear(m, omega)
    variational = monodromy.monodromy_variational(m, lambda tau: (np.zeros((1, 1)), np.zeros((1, 1))), omega)
    np.testing.assert_allclose(magnus, variational, rtol=1e-7, atol=1e-9 * np.abs(magnus).max())


def _hand_written_monodromy(m, omega, with_friction_parameter):
    """Monodromy of ``m_e y'' = -G(s) (k(s) y + c y')`` over a mesh period, written here from the
    equations of motion (not from the model's force): formulation B's normal loads
    ``sigma_j F_mesh`` put the friction torques ``T_fp = -sum mu_j sigma_j F xi_p,j``,
    ``T_fg = +sum mu_j sigma_j F xi_g,j`` into the DTE equation
    ``m_e delta'' = N - F + m_e (T_fp/(R_bp m_p) - T_fg/(R_bg m_g))`` as the factor
    ``G = 1 + m_e mu0 sum_j sigma_j sgn(xi_p,j - x_P) (xi_p,j/(R_bp m_p) + xi_g,j/(R_bg m_g))`` on the
    mesh force (``G = 1`` in formulation A). DOP853 at rtol 1e-12 between the breakpoints."""
    from scipy.integrate import solve_ivp

    tm = 2 * np.pi / (m.teeth_pinion * omega)
    me, mp, mg = m.mass_equivalent_kg, m.mass_pinion_kg, m.mass_gear_kg
    rbp, rbg, length, pitch, start = (m.base_radius_pinion_m, m.base_radius_gear_m, m.line_of_action_m,
                                      m.base_pitch_m, m.contact_start_m)
    double = m.contact_ratio - 1.0
    x_pitch = length * m.teeth_pinion / (m.teeth_pinion + m.teeth_gear)
    damping = m.mesh_damping_Ns_per_m

    def gain(s):
        slots = (0, 1) if s < double else (0,)
        xi = start + pitch * (s + np.array(slots))
        arms = np.sign(xi - x_pitch) * (xi / (rbp * mp) + (length - xi) / (rbg * mg))
        return 1.0 + with_friction_parameter * me * m.friction.mu0 * np.mean(arms)

    crossing = (x_pitch - start) / pitch
    edges = sorted({0.0, double, 1.0} | {crossing - k for k in (0, 1) if 0 < crossing - k < 1})
    phi = np.eye(2)
    for a, b in zip(edges[:-1], edges[1:]):
        k = m.k_max_N_per_m if 0.5 * (a + b) < double else m.k_min_N_per_m

        def rhs(t, y, a=a, b=b, k=k):
            s = min(max(t / tm, a + 1e-13), b - 1e-13)
            y = y.reshape(2, 2)
            return np.concatenate([y[1], -(gain(s) / me) * (k * y[0] + damping * y[1])])

        phi = solve_ivp(rhs, (a * tm, b * tm), phi.ravel(), method="DOP853", rtol=1e-12,
                        atol=1e-14 * np.abs(phi).max()).y[:, -1].reshape(2, 2)
    return phi


def _matched(reference, other):
    d = np.abs(np.asarray(reference)[:, None] - np.asarray(other)[None, :])
    return np.asarray(other)[linear_sum_assignment(d)[1]]


@pytest.mark.parametrize("rpm", [26000.0, 13400.0])
def test_formulation_b_shift_of_the_multipliers_pinned_by_an_independent_integration(rpm):
    """The multipliers of B, and their shift from A, against the hand-written equations above.
    Measured: A exact vs hand-written 1e-13 / 7e-13; B (Magnus, 16 steps per segment) vs
    hand-written 1.3e-10 / 2.5e-9; the shift B - A (|shift| 3.3e-3 at 26000 rpm, 3.0e-2 at 13400)
    agrees to 4e-8 / 8e-8 of itself. A wrong sign or arm of the friction parameter fails here,
    not only one that leaves A = B."""
    omega = rpm / RPM
    a_exact = monodromy.multipliers_linear(model("torques"), omega)
    # LTV-B along states with F_mesh > 0: its linear equivalent, the signed loads sigma_j F_mesh
    b_model = monodromy.multipliers_linear(model("torques", formulation="B").replace(normal_loads="signed"), omega)
    a_hand = np.linalg.eigvals(_hand_written_monodromy(model("torques"), omega, 0.0))
    b_hand = np.linalg.eigvals(_hand_written_monodromy(model("torques", formulation="B"), omega, 1.0))
    assert max_pair_distance(a_exact, a_hand) < 1e-11
    assert max_pair_distance(b_model, b_hand) < 1e-8
    shift_model = _matched(a_exact, b_model) - a_exact
    shift_hand = _matched(a_exact, b_hand) - a_exact
    assert np.max(np.abs(shift_hand)) > 1e-3
    assert np.max(np.abs(shift_model - shift_hand)) < 1e-6 * np.max(np.abs(shift_hand))


def test_variational_state_synthesis_equals_the_solution_and_a_state_function():
    """The monodromy's own synthesis of ``(q, q')`` (one matrix product per instant) equals
    ``PeriodicSolution.state_at``, and the monodromy is the same whether it gets the solution or
    ``state_at`` as a plain function (NLTV arctan, soft spring, near the 5270 rpm crossing)."""
    from hbgear.gear.solve import solve_periodic

    m = build_model(config("friction.model='NLTV'", "friction.law='arctan'"))
    omega = 5300.0 / RPM
    sol = solve_periodic(m, omega, harmonics=16, samples=128)
    from hbgear.engine.monodromy import state_synthesis

    synthesis = state_synthesis(sol.coefficients, sol.harmonics, sol.base_frequency)
    tau = np.array([0.0, 0.123, 0.5, 0.987])
    q, qd = sol.state_at(tau)
    for j, t in enumerate(tau):
        qs, qds = synthesis(t)
        np.testing.assert_allclose(qs, q[:, j], rtol=1e-13, atol=1e-13 * np.abs(q).max())
        np.testing.assert_allclose(qds, qd[:, j], rtol=1e-13, atol=1e-13 * np.abs(qd).max())
    from_solution = monodromy.monodromy_variational(m, sol, omega)
    # the same solution through the generic path (a callable; its wind-up from the model)
    assert sol.u_static_m == pytest.approx(float(m.static_windup(omega)), rel=1e-12)
    from_function = monodromy.monodromy_variational(m, sol.state_at, omega)
    np.testing.assert_allclose(from_solution, from_function, rtol=1e-9, atol=1e-11 * np.abs(from_function).max())


def test_variational_monodromy_batch_equals_the_members_alone():
    """A batch of three solutions (padded to four members) integrated together: each member's
    monodromy and most negative real multiplier as when integrated alone (NLTV arctan, soft
    spring, around the 5270 rpm crossing); members with other breakpoints are refused."""
    from hbgear.engine import bifurcation
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.monodromy import monodromy_variational, state_synthesis
    from hbgear.gear.solve import solve_periodic
    from hbgear.gear.system import GearSystem

    m = build_model(config("friction.model='NLTV'", "friction.law='arctan'"))
    omegas = np.array([5250.0, 5270.0, 5290.0]) / RPM
    sols = [solve_periodic(m, w, harmonics=16, samples=128) for w in omegas]
    system = GearSystem(m)
    batch = monodromy_variational(system, omegas, state_synthesis(np.stack([s.coefficients for s in sols]), 16,
                                                                  np.array([s.base_frequency for s in sols])))
    assert batch.shape == (3, 4, 4)
    for phi, sol, w in zip(batch, sols, omegas):
        alone = monodromy_variational(system, w, state_synthesis(sol.coefficients, 16, sol.base_frequency))
        np.testing.assert_allclose(phi, alone, rtol=1e-8, atol=1e-8 * np.abs(alone).max())
    hb = HarmonicBalance(m.ndof, 16, 1, 128)
    together = bifurcation.exact_negative_multipliers(system, hb, [s.z for s in sols], omegas)
    for value, sol, w in zip(together, sols, omegas):
        assert value == pytest.approx(bifurcation.exact_negative_multiplier(system, hb, sol.z, w), abs=1e-8)
    other = build_model(config("friction.model='NLTV'", "friction.law='arctan'", "gear.contact_ratio=1.5"))

    class TwoGeometries(GearSystem):
        coefficients_independent_of_parameter = False  # its breakpoints depend on p (a system that
        # declares them independent is taken at its word: the first member's serve the batch)

        def breakpoints(self, p, xp=np):
            return (other if p > omegas[0] else m).breakpoint_candidates(xp)

    with pytest.raises(ValueError, match="same breakpoints"):
        monodromy_variational(TwoGeometries(m), omegas[:2], lambda tau: (np.zeros((2, 2)), np.zeros((2, 2))))


def test_compiled_variational_monodromy_equals_scipys_dop853():
    """The variational equations integrated inside one compiled program (Dormand-Prince 5(4),
    hbgear.engine.dopri) against SciPy's DOP853 driven from Python, an integrator of another
    order and code: the same monodromy matrices (NLTV arctan, soft spring, H = 16, three speeds
    about the 5270 rpm crossing and one at 12000 rpm, batched; one alone); a state that is not a
    synthesis cannot take the compiled way; an unknown integrator is refused."""
    from hbgear.engine.monodromy import monodromy_variational, state_synthesis
    from hbgear.gear.solve import solve_periodic

    m = build_model(config("friction.model='NLTV'", "friction.law='arctan'"))
    omegas = np.array([5250.0, 5270.0, 5290.0, 12000.0]) / RPM
    sols = [solve_periodic(m, w, harmonics=16, samples=128) for w in omegas]
    system = GearSystem(m)
    state = state_synthesis(np.stack([s.coefficients for s in sols]), 16, np.array([s.base_frequency for s in sols]))
    compiled = monodromy_variational(system, omegas, state, integrator="compiled")
    scipy_dop853 = monodromy_variational(system, omegas, state, integrator="DOP853")
    assert compiled.shape == (4, 4, 4)
    for a, b in zip(compiled, scipy_dop853):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.abs(b).max())
        np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(a)), np.sort_complex(np.linalg.eigvals(b)),
                                   rtol=0, atol=1e-8)
    alone = monodromy_variational(system, omegas[1], state_synthesis(sols[1].coefficients, 16, sols[1].base_frequency))
    np.testing.assert_allclose(alone, scipy_dop853[1], rtol=0, atol=1e-8 * np.abs(alone).max())
    with pytest.raises(ValueError, match="state_synthesis"):
        monodromy_variational(system, omegas[0], sols[0].state_at, integrator="compiled")
    with pytest.raises(ValueError, match="allowed"):
        monodromy_variational(system, omegas[0], state, integrator="RK4")


def test_branch_stability_takes_the_variational_equations_and_hill_on_request(monkeypatch):
    """A branch's multipliers come from the variational equations (compiled), or from Hill's
    method with ``method="hill"`` while its matrices are at most ``HILL_MAX_SIZE`` square (the
    NLTV pair at 200 rpm, H = 512: Hill took 84 s a point there and returned a spurious third
    multiplier). NLTV arctan, H = 32, N = 1024 (Hill's size 130): the two routes' multipliers
    within 1e-4 (3.6e-5 measured; 3.6e-3 at N = 256, where Hill's matrices alias the friction's
    sign change; they share no code but the harmonic-balance solutions), the same verdicts, each
    method named; with the limit lowered below 130, Hill's request gets the variational equations,
    with the reason."""
    from hbgear.engine import stability
    from hbgear.gear.solve import solve_periodic

    m = build_model(config("friction.model='NLTV'", "friction.law='arctan'"))
    system = GearSystem(m)
    hb = HarmonicBalance(m.ndof, 32, 1, 1024)
    omegas = np.array([5200.0, 5300.0, 5400.0, 8700.0]) / RPM  # in and out of two period-doubling zones
    zs = np.stack([solve_periodic(m, w, harmonics=32, samples=1024).z for w in omegas])
    default = stability.branch_stability(hb, system, omegas, zs, progress=False)
    assert default.method.startswith("the variational equations") and default.warning is None
    hill = stability.branch_stability(hb, system, omegas, zs, method="hill", progress=False)
    assert stability.uses_hill(hb) and hill.method.startswith("Hill's method")
    monkeypatch.setattr(stability, "HILL_MAX_SIZE", hb.size - 1)
    assert not stability.uses_hill(hb)
    beyond = stability.branch_stability(hb, system, omegas, zs, method="hill", progress=False)
    assert beyond.method.startswith("the variational equations") and "130 > 129" in beyond.method
    for a, b, c in zip(hill.multipliers, default.multipliers, beyond.multipliers):
        assert max_pair_distance(a, b) < 1e-4, (a, b)
        assert max_pair_distance(b, c) < 1e-12, (b, c)
    np.testing.assert_array_equal(hill.stable, default.stable)
    assert list(default.stable) == [1.0, 0.0, 1.0, 0.0]
    with pytest.raises(ValueError, match="allowed"):
        stability.branch_stability(hb, system, omegas, zs, method="dense")


def test_a_force_that_jumps_with_the_state_takes_hill():
    """Backlash with friction declares the flank contacts as event functions (its friction load
    jumps where a flank opens): the branch's multipliers are Hill's, the reason named."""
    from hbgear.engine import stability
    from hbgear.engine.events import declared
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.gear.solve import solve_periodic

    m = build_model(load_config(EXAMPLE.parent / "backlash.toml", ["friction.law='arctan'", "friction.mu0=0.05"]))
    system = GearSystem(m)
    assert declared(system, 13000.0 / RPM)
    hb = HarmonicBalance(m.ndof, 8, 1, 128)
    omegas = np.array([13000.0, 13100.0]) / RPM  # the flanks separate: out of the linear regime
    zs = [solve_periodic(m, omegas[0], harmonics=8, samples=128).z]
    zs.append(solve_periodic(m, omegas[1], harmonics=8, samples=128, z0=zs[0]).z)
    assert not any(system.in_linear_regime(hb, z, w) for z, w in zip(zs, omegas))
    result = stability.branch_stability(hb, system, omegas, np.stack(zs), progress=False)
    assert result.method.startswith("Hill's method") and "saltation" in result.method, result.method
    for w, z, mult in zip(omegas, zs, result.multipliers):
        assert max_pair_distance(mult, hill_multipliers(hb, z, float(w), system)) < 1e-10


def test_points_near_a_fold_take_hill_so_the_verdict_changes_at_the_fold():
    """Within ``FOLD_WINDOW`` points of a fold index the multipliers are Hill's (the harmonic-
    balance Jacobian's), elsewhere the variational equations'; the method text says both."""
    from hbgear.engine import stability
    from hbgear.engine.floquet import hill_multipliers
    from hbgear.gear.solve import solve_periodic

    m = build_model(config("friction.model='NLTV'", "friction.law='arctan'"))
    system = GearSystem(m)
    hb = HarmonicBalance(m.ndof, 16, 1, 256)
    omegas = np.linspace(6000.0, 6400.0, 12) / RPM
    zs = np.stack([solve_periodic(m, w, harmonics=16, samples=256).z for w in omegas])
    mixed = stability.branch_stability(hb, system, omegas, zs, folds=[0], progress=False)
    assert "the variational equations" in mixed.method and "Hill's method (hbgear.engine.floquet" in mixed.method
    window = stability.FOLD_WINDOW
    for i, (w, z) in enumerate(zip(omegas, zs)):
        alone = hill_multipliers(hb, z, float(w), system)
        distance = max_pair_distance(mixed.multipliers[i], alone)
        assert (distance < 1e-10) == (i <= window), (i, distance)
# ----------------------------------------------------------------------------- tongues


def test_map_reproduces_parametric_tongues():
    m = model("torques", zeta=0.005)
    centres = [tongue_rpm(m, j) for j in (1, 3)]
    between = [tongue_rpm(m, 1.5), tongue_rpm(m, 2.5), tongue_rpm(m, 3.5)]
    values = maps.stability_map_ltv_a([m], centres + between)[0]
    assert np.all(values[:2] > 1.0), values
    assert np.all(values[2:] < 1.0), values
    # j = 2 (even: a fold, multiplier through +1) is narrow; a light damping and a fine scan
    light = model("torques", zeta=0.001)
    scan = np.linspace(0.97, 1.01, 401) * tongue_rpm(light, 2)
    assert maps.stability_map_ltv_a([light], scan)[0].max() > 1.0
    # types of instability: real multiplier through -1 (odd j), through +1 (even j)
    odd = monodromy.multipliers_linear(m, centres[0] / RPM)
    assert floquet.period_doubling(odd) and floquet.classify(odd).kind == "period-doubling"
    worst = scan[np.argmax(maps.stability_map_ltv_a([light], scan)[0])]
    even = monodromy.multipliers_linear(light, worst / RPM)
    assert not floquet.period_doubling(even) and floquet.classify(even).kind == "fold"


def test_map_holds_tooth_stiffnesses_and_shifts_zone_with_contact_ratio():
    cfg = config('boundary.output="torques"')
    lo, hi = model_at_contact_ratio(cfg, 1.35), model_at_contact_ratio(cfg, 1.65)
    assert lo.k_min_N_per_m == hi.k_min_N_per_m and lo.k_max_N_per_m == hi.k_max_N_per_m
    speeds = np.linspace(20000, 32000, 121)
    values = maps.stability_map_ltv_a([lo, hi], speeds)
    centre = [np.average(speeds, weights=np.clip(v - 1, 0, None)) for v in values]
    assert centre[1] > centre[0] + 500  # k_mean grows with Gamma


# ----------------------------------------------------------------------------- command


@pytest.fixture
def small_config():
    return config(
        'boundary.output="torques"',
        "map.speed_steps=6",
        "map.contact_ratio_steps=3",
        "map.speed_rpm_start=24000.0",
        "map.speed_rpm_stop=30000.0",
    )


def test_dask_path_equals_local_path(small_config, tmp_path):
    distributed = pytest.importorskip("dask.distributed")
    from hbgear.cli import stability_map as cmd

    local = cmd.run_map(small_config, tmp_path / "local", progress=False)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cluster:
        remote = cmd.run_map(small_config, tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    np.testing.assert_array_equal(local[2], remote[2])
    assert (tmp_path / "dask" / "stability.csv").read_text() == (tmp_path / "local" / "stability.csv").read_text()
    assert not (tmp_path / "dask" / cmd.PARTIAL).exists()


def test_resume_skips_finished_rows(small_config, tmp_path, monkeypatch):
    from hbgear.cli import stability_map as cmd

    speeds, ratios = cmd.grid(small_config)
    fingerprint = cmd._fingerprint(small_config, speeds, ratios)
    finished = {0: np.full(len(speeds), 0.25), 2: np.full(len(speeds), 0.75)}
    text = fingerprint + "\nspeed_rpm,contact_ratio,max_abs_floquet\n"
    text += cmd._row_lines(ratios[0], speeds, finished[0]) + cmd._row_lines(ratios[2], speeds, finished[2])
    text += cmd._row_lines(ratios[1], speeds[:2], [9.0, 9.0])  # an incomplete row ...
    text += f"{speeds[2]!r},{ratios[1]!r},9."  # ... cut by a crash
    (tmp_path / cmd.PARTIAL).write_text(text)
    calls = []
    real = cmd.compute_row

    def counting(cfg, ratio, sp):
        calls.append(ratio)
        return real(cfg, ratio, sp)

    monkeypatch.setattr(cmd, "compute_row", counting)
    _, _, values = cmd.run_map(small_config, tmp_path, progress=False)
    assert calls == [ratios[1]]
    np.testing.assert_array_equal(values[0], finished[0])
    np.testing.assert_array_equal(values[2], finished[2])
    np.testing.assert_allclose(values[1], real(small_config, ratios[1], speeds))
    assert not (tmp_path / cmd.PARTIAL).exists()
    lines = (tmp_path / "stability.csv").read_text().splitlines()
    assert lines[0] == "speed_rpm,contact_ratio,max_abs_floquet" and len(lines) == 1 + 18

    # a partial file of another configuration is not trusted
    (tmp_path / cmd.PARTIAL).write_text(text.replace("sha256=", "sha256=0"))
    calls.clear()
    cmd.run_map(small_config, tmp_path, progress=False)
    assert len(calls) == 3


def test_cli_writes_outputs_and_missing_dask_is_bad_input(tmp_path, monkeypatch, capsys):
    import sys

    from hbgear import cli
    from hbgear.cli import stability_map  # noqa: F401  (registers the command)

    args = ["stability-map", str(EXAMPLE), "--out", str(tmp_path / "o"), "--no-progress"]
    args += ["--set", "map.speed_steps=5", "--set", "map.contact_ratio_steps=2"]
    assert cli.main(args) == 0
    assert {p.name for p in (tmp_path / "o").iterdir()} == {"stability.csv", "stability.png"}
    monkeypatch.setitem(sys.modules, "dask.distributed", None)
    assert cli.main(args[:4] + ["--scheduler", "tcp://127.0.0.1:1"]) == 2
    assert "install hbgear[distributed]" in capsys.readouterr().err


def test_stable_verdicts_rows_follow_the_single_point_rule():
    """floquet.stable_verdicts (rows at once) against the rule written out point by point: drop the
    nearest multiplier within TRIVIAL_TOL of each known neutral one, then stable iff what is left is
    non-empty, finite and inside 1 + 1e-9."""

    class Neutral:
        def neutral_multipliers(self, p, nu=1):
            p = np.asarray(p, dtype=float)
            return np.stack([np.exp(1j * p), np.exp(-1j * p)], axis=-1)

    rng = np.random.default_rng(7)
    ps = rng.uniform(0.1, 3.0, 400)
    mult = (rng.uniform(0.5, 1.1, (400, 4)) * np.exp(1j * rng.uniform(-np.pi, np.pi, (400, 4))))
    hit = rng.random(400) < 0.5
    mult[hit, 1] = np.exp(1j * ps[hit]) * (1 + 1e-9)  # a neutral pair, one slightly off
    mult[hit, 3] = np.exp(-1j * ps[hit])
    mult[::37, 2] = np.nan
    mult[5] = [np.exp(1j * ps[5]), np.exp(-1j * ps[5]), np.exp(1j * ps[5]), 0.2]  # one neutral copy too many
    mult[6, :2] = [np.exp(1j * ps[6]), np.exp(-1j * ps[6])]

    def by_hand(p, m):
        left = list(m)
        for target in (np.exp(1j * p), np.exp(-1j * p)):
            d = [abs(x - target) for x in left]
            j = int(np.argmin(d))
            if d[j] <= floquet.TRIVIAL_TOL:
                left.pop(j)
        left = np.abs(np.asarray(left))
        return bool(left.size and np.all(np.isfinite(left)) and left.max() <= 1.0 + 1e-9)

    want = [by_hand(p, m) for p, m in zip(ps, mult)]
    assert 50 < sum(want) < 350
    np.testing.assert_array_equal(floquet.stable_verdicts(Neutral(), ps, mult), want)
    assert [floquet.stable_verdict(Neutral(), p, m) for p, m in zip(ps[:40], mult[:40])] == want[:40]
    only_neutral = np.array([[np.exp(1j * 0.3), np.exp(-1j * 0.3)]])
    assert not floquet.stable_verdicts(Neutral(), [0.3], only_neutral)[0]  # nothing left: no verdict


def test_a_point_whose_multipliers_fail_is_nan_and_named_and_its_batch_is_kept(monkeypatch):
    """A batch that raises is redone point by point (Hill: its follower reset; the variational
    equations: one integration a point): the good points keep their multipliers, the bad one is
    NaN, its parameter named in the warning."""
    from hbgear.engine import stability
    from hbgear.engine.system import Duffing

    from hbgear.engine.response import newton_solve

    hb = HarmonicBalance(1, 5, 1, 64)
    system = Duffing(0.02, 1.0, 0.1, 0.05)
    ps = np.array([0.7, 0.8, 0.9, 1.3])
    zs = np.stack([newton_solve(hb, system, p, np.zeros(hb.size), tolerance=1e-10).z for p in ps])
    bad = 0.9
    # the retried points are recomputed one by one: Hill's refinement from other seeds (to its
    # refined tolerance), the variational equations with a step control of their own (VARIATIONAL_RTOL 1e-8)
    for method, name, rtol in (("hill", "hill_exponents_along", 5e-12), ("variational", None, 1e-7)):
        good = stability.branch_stability(hb, system, ps, zs, method=method, progress=False)
        assert good.warning is None
        with monkeypatch.context() as patch:
            if name:  # the batch fails, then the one bad point
                along, single = stability.hill_exponents_along, stability.hill_multipliers
                patch.setattr(stability, name, lambda hb_, zs_, ps_, *a, **k: (
                    _raise() if bad in ps_ else along(hb_, zs_, ps_, *a, **k)))
                patch.setattr(stability, "hill_multipliers", lambda hb_, z, p, *a, **k: (
                    _raise() if p == bad else single(hb_, z, p, *a, **k)))
            else:
                from hbgear.engine import monodromy

                integrate = monodromy.monodromy_variational
                patch.setattr(monodromy, "monodromy_variational", lambda system_, ps_, *a, **k: (
                    _raise() if bad in np.atleast_1d(ps_) else integrate(system_, ps_, *a, **k)))
            broken = stability.branch_stability(hb, system, ps, zs, method=method, progress=False)
        assert "failed at 1 point(s)" in broken.warning and "p = 0.9: RuntimeError: injected" in broken.warning
        assert np.isnan(broken.max_abs[2]) and np.isnan(broken.stable[2])
        for i in (0, 1, 3):
            np.testing.assert_allclose(broken.multipliers[i], good.multipliers[i], rtol=rtol)


def _raise():
    raise RuntimeError("injected")
