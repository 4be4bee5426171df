"""The structured (matrix-free) path for many harmonics, checked against the dense path at small
H: the lattice quadrature against the kernel, GMRES against a direct solve, the residual, the
Jacobian products and the converged solutions of the structured path against the dense one
(LTV, NLTV, backlash with the reaction boundary, formulation B with speed-dependent
coefficients, Duffing), and the memory bound: the structured pieces hold no (size x size)
array and grow linearly with H, and the whole solve -> read-outs -> Floquet path runs without
any dense operator (the size rule lowered so that it runs at small H)."""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hbgear.engine.hb as hb_module
import hbgear.gear.solve as solve_module
from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.engine import fourier
from hbgear.engine.floquet import hill_multipliers
from hbgear.engine.hb import HarmonicBalance, residual_functions
from hbgear.engine.krylov import gmres
from hbgear.engine.newton import newton
from hbgear.engine.quadrature import (fourier_coefficients, lattice_coefficients, lattice_rule, lattice_synthesis,
                                      mesh_period_rule)
from hbgear.engine.structured import BORDERED_RTOL, KrylovJacobian, product_samples
from hbgear.engine.system import Duffing
from hbgear.engine.response import solution_multipliers as engine_multipliers
from hbgear.gear.monodromy import floquet_multipliers
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
from hbgear.gear.system import GearSystem

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"

GEAR_CASES = {
    "LTV": ["friction.model='LTV'"],
    "NLTV": ["friction.model='NLTV'", "friction.law='arctan'"],
    "backlash": ["friction.model='NLTV'", "friction.law='arctan'", "mesh.backlash_um=20.0",
                 "boundary.output='reaction'"],
    "LTV-B arctan": ["friction.model='LTV'", "friction.law='arctan'", "friction.formulation='B'"],
}


def solution_multipliers(solution):
    """The Floquet multipliers the solve path computes for a solution (the engine's choice)."""
    return engine_multipliers(solution.hb, solution.system, solution.z, solution.parameter)


def gear(case):
    model = build_model(load_config(EXAMPLE, GEAR_CASES[case]))
    # backlash compared with signed friction loads: no jumps where a flank closes (the structured
    # path does not carry them: test_structured_refuses_event_jumps_and_auto_falls_back)
    return model.replace(normal_loads="signed") if case == "backlash" else model


def pair(ndof, harmonics, samples, nu=1):
    return tuple(HarmonicBalance(ndof, harmonics, nu, samples, operator=op) for op in ("dense", "structured"))


# -- the lattice quadrature and GMRES --------------------------------------------------------------


@pytest.mark.parametrize("order", [4, 40, 300])
def test_lattice_rule_is_the_mesh_period_rule_and_its_sums_are_the_kernel_sums(order):
    breakpoints = np.array([0.0, 0.17, 0.43, 0.43, 0.61, 0.9, 1.0])
    s, w = mesh_period_rule(breakpoints, order)
    rule = lattice_rule(breakpoints, order)
    np.testing.assert_array_equal(rule.nodes, s)
    np.testing.assert_array_equal(rule.weights, w)
    values = np.random.default_rng(0).normal(size=(3, 2, s.size))
    expected = fourier_coefficients(values, s, w, order)
    got = lattice_coefficients(values, rule)
    assert np.max(np.abs(got - expected)) <= 1e-13 * np.max(np.abs(expected)) * max(1, order / 10)
    got_jax = jax.jit(lambda v, r: lattice_coefficients(v, r, jnp))(values, rule)
    np.testing.assert_allclose(np.asarray(got_jax), got, rtol=0, atol=1e-13 * np.max(np.abs(got)))
    c = np.random.default_rng(1).normal(size=(2, order + 1)) + 1j * np.random.default_rng(2).normal(size=(2, order + 1))
    for shift, scale in ((0.0, 1.0), (0.5, 0.5)):
        direct = (c @ np.exp(2j * np.pi * np.outer(np.arange(order + 1), shift + scale * s))).real
        got = lattice_synthesis(c, rule, shift, scale, block=500)  # small blocks: the chunked loop runs
        assert np.max(np.abs(got - direct)) <= 1e-13 * np.max(np.abs(direct)) * max(1, order / 10)


def test_differentiate_is_the_derivative_matrix():
    x = np.random.default_rng(3).normal(size=(2, 3, 2 * 9 + 1))
    np.testing.assert_array_equal(fourier.differentiate(x, 9, 2.5), x @ fourier.derivative_matrix(9, 2.5).T)


# -- the structured path gives the dense path's answers -------------------------------------------


def _compare(dense, structured, system, z, p):
    """Residual, (R, J) products and the dense entry points of both discretisations at (z, p)."""
    r_d = np.asarray(dense.residual(jnp.asarray(z), p, system))
    r_s = np.asarray(structured.residual(jnp.asarray(z), p, system))
    np.testing.assert_allclose(r_s, r_d, rtol=0, atol=1e-10)  # scaled: relative to the force scale
    _, jac = dense.residual_and_linearization(jnp.asarray(z), p, system)
    r_l, lin = structured.residual_and_linearization(jnp.asarray(z), p, system)
    np.testing.assert_allclose(np.asarray(r_l), r_s, rtol=0, atol=1e-14)
    jac = np.asarray(jac)
    for seed in range(3):
        v = np.random.default_rng(seed).normal(size=dense.size)
        np.testing.assert_allclose(lin.matvec(v), jac @ v, rtol=0, atol=1e-10 * np.max(np.abs(jac @ v)))
    # the dense entry points (continuation, Hill) still work on the structured pieces
    _, jac_s, jp_s = structured.residual_and_jacobians(jnp.asarray(z), p, system)
    _, _, jp_d = dense.residual_and_jacobians(jnp.asarray(z), p, system)
    np.testing.assert_allclose(np.asarray(jac_s), jac, rtol=0, atol=1e-10 * np.max(np.abs(jac)))
    np.testing.assert_allclose(np.asarray(jp_s), np.asarray(jp_d), rtol=0, atol=1e-10 * np.max(np.abs(jp_d)))


def _newton(hb, system, p, z0, linear_rtol=None):
    prepared = hb.prepare(system)
    return newton(lambda z: hb.residual_and_linearization(jnp.asarray(z), p, system, prepared),
                  lambda z: hb.residual(jnp.asarray(z), p, system, prepared), z0, tolerance=1e-12,
                  linear_rtol=linear_rtol)


@pytest.mark.parametrize("case", list(GEAR_CASES))
@pytest.mark.parametrize("samples", [72, 56])  # N > 4H (Toeplitz dense Jacobian) and N <= 4H (jacfwd)
def test_structured_gear_pair_equals_dense(case, samples):
    model = gear(case)
    system, omega, harmonics = GearSystem(model), rpm_to_rad_s(9000.0), 16
    dense, structured = pair(model.ndof, harmonics, samples)
    assert structured.prepare(system).structured is not None and dense.prepare(system).structured is None
    reference = solve_periodic(model, omega, harmonics=harmonics, samples=samples, tolerance=1e-12)
    z = reference.z * (1 + 0.02 * np.random.default_rng(5).normal(size=reference.z.size))
    _compare(dense, structured, system, z, omega)
    linear_rtol = 1e-13 if model.is_linear else None
    ours = _newton(structured, system, omega, reference.z * 0.9, linear_rtol)
    theirs = _newton(dense, system, omega, reference.z * 0.9)
    assert ours.converged and theirs.converged and ours.linear_iterations > 0
    _same_solution(dense, system, omega, ours.z, theirs.z)


def _same_solution(dense, system, p, ours, theirs):
    """The DTE's coefficients to 1e-10; all unknowns in the norm the residual sees, |J (z1 - z2)|
    <= 1e-10 (the soft spring's mean, ~1/5e5 of a force per unit, is known only that well)."""
    block = dense.block
    np.testing.assert_allclose(ours[:block], theirs[:block], rtol=0, atol=1e-10 * np.max(np.abs(theirs[:block])))
    _, jac = dense.residual_and_linearization(jnp.asarray(theirs), p, system)
    assert np.max(np.abs(np.asarray(jac) @ (ours - theirs))) <= 1e-10


def test_structured_refuses_event_jumps_and_auto_falls_back(monkeypatch):
    """Backlash with compressive friction loads declares event functions (the loads jump where a
    flank closes): operator='structured' refuses with a message naming the way out, and 'auto'
    takes the dense path even where its size rule would choose the structured one."""
    model = build_model(load_config(EXAMPLE, GEAR_CASES["backlash"]))
    system = GearSystem(model)
    with pytest.raises(ValueError, match="operator='dense' or 'auto'"):
        HarmonicBalance(model.ndof, 8, 1, 40, operator="structured").prepare(system)
    monkeypatch.setattr(hb_module, "STRUCTURED_MIN_SIZE", 1, raising=False)
    auto = HarmonicBalance(model.ndof, 8, 1, 40, operator="auto")
    assert auto.prepare(system).structured is None


@pytest.mark.parametrize("samples", [64, 20])
def test_structured_duffing_equals_dense(samples):
    system, p = Duffing(), 1.2
    dense, structured = pair(1, 7, samples)
    z = np.random.default_rng(6).normal(size=dense.size) * 0.3
    _compare(dense, structured, system, z, p)
    ours, theirs = _newton(structured, system, p, np.zeros(dense.size)), _newton(dense, system, p, np.zeros(dense.size))
    assert ours.converged and theirs.converged
    np.testing.assert_allclose(ours.z, theirs.z, rtol=0, atol=1e-10 * np.max(np.abs(theirs.z)))
    _same_solution(dense, system, p, ours.z, theirs.z)


def test_structured_subharmonic_nu2_equals_dense():
    model = gear("NLTV")
    system, omega = GearSystem(model), rpm_to_rad_s(11000.0)
    dense, structured = pair(model.ndof, 12, 2 * 56, nu=2)
    z = solve_periodic(model, omega, harmonics=12, nu=2, samples=112).z
    _compare(dense, structured, system, z * 1.01, omega)


# -- the memory bound, at small size through the same code path --------------------------------------


def _arrays(tree):
    return [np.shape(leaf) for leaf in jax.tree_util.tree_leaves(tree) if np.ndim(leaf) > 0]


def _bytes(tree):
    return sum(np.asarray(leaf).nbytes for leaf in jax.tree_util.tree_leaves(tree))


@pytest.mark.parametrize("case", ["NLTV", "LTV-B arctan"])
def test_structured_pieces_hold_no_size_by_size_array_and_grow_linearly(case):
    model = gear(case)
    system, omega = GearSystem(model), rpm_to_rad_s(9000.0)
    sizes = {}
    for harmonics in (16, 64):
        _, hb = pair(model.ndof, harmonics, 4 * harmonics + 8)
        prepared = hb.prepare(system)
        assert prepared.frozen is None and prepared.kernel_cos is None and prepared.kernel_sin is None
        z = solve_periodic(model, omega, harmonics=harmonics, samples=4 * harmonics + 8).z
        _, lin = hb.residual_and_linearization(jnp.asarray(z), omega, system, prepared)
        for shape in _arrays((prepared, lin.linearization)):
            assert len(shape) < 2 or sorted(shape)[-2] < hb.size, shape  # never two axes of the problem's size
        sizes[harmonics] = _bytes((prepared, lin.linearization))
    assert sizes[64] < 4.6 * sizes[16]  # linear in H (x4); a size x size piece would be x16


def test_solve_readouts_and_floquet_run_without_dense_operators_at_small_size(monkeypatch):
    """With the size rule lowered to 0, solve_periodic, the read-outs and the Floquet multipliers
    take the structured path (no dense operator, kernel or Hill matrix built) and agree with the
    dense path (solution, read-outs to 1e-10; multipliers: variational equations vs Hill)."""
    model = gear("NLTV")
    omega, harmonics, samples = rpm_to_rad_s(3000.0), 24, 104
    dense = solve_periodic(model, omega, harmonics=harmonics, samples=samples, tolerance=1e-12)
    dense_summary, hill = dense.summary(), solution_multipliers(dense)

    def forbidden(*args, **kwargs):
        raise AssertionError("a dense operator was built on the structured path")

    monkeypatch.setattr(hb_module, "STRUCTURED_MIN_SIZE", 0)
    monkeypatch.setattr(solve_module, "READ_OUT_LATTICE_HARMONICS", 0)
    solve_module._read_out_rule.cache_clear()
    for name in ("linear_operator", "_frozen_operator", "_rule", "_nonlinear_jacobian", "hill_matrices"):
        monkeypatch.setattr(HarmonicBalance, name, forbidden)
    try:
        ours = solve_periodic(model, omega, harmonics=harmonics, samples=samples, tolerance=1e-12)
        summary, variational = ours.summary(), solution_multipliers(ours)
    finally:
        solve_module._read_out_rule.cache_clear()
    hb = HarmonicBalance(model.ndof, harmonics, 1, samples, operator="dense")
    monkeypatch.undo()
    _same_solution(hb, GearSystem(model), omega, ours.z, dense.z)
    for key, value in dense_summary.items():
        assert summary[key] == pytest.approx(value, rel=1e-10, abs=1e-12), key
    # the variational equations along the dense solution at the structured path's tolerances (the
    # paths' difference alone), and at rtol 1e-10 within the 1e-8 integration's error (6e-8 here);
    # Hill (H = 24) on the dominant multiplier
    from hbgear.engine.stability import VARIATIONAL_ATOL, VARIATIONAL_RTOL
    from hbgear.gear.monodromy import monodromy_variational

    same = np.linalg.eigvals(monodromy_variational(model, dense, omega, rtol=VARIATIONAL_RTOL, atol=VARIATIONAL_ATOL))
    np.testing.assert_allclose(np.sort(np.abs(variational)), np.sort(np.abs(same)), rtol=1e-10)
    reference = floquet_multipliers(model, omega, solution=dense, method="variational")
    np.testing.assert_allclose(np.sort(np.abs(variational)), np.sort(np.abs(reference)), rtol=2e-7)
    assert np.max(np.abs(variational)) == pytest.approx(np.max(np.abs(hill)), rel=1e-6)


def test_state_on_grid_is_state_at_on_the_uniform_grid():
    model = gear("NLTV")
    sol = solve_periodic(model, rpm_to_rad_s(5000.0), harmonics=16, samples=72)
    q, qd = sol.state_on_grid(100)
    q_ref, qd_ref = sol.state_at(np.arange(100) / 100)
    np.testing.assert_allclose(q, q_ref, rtol=0, atol=1e-13 * np.max(np.abs(q_ref)))
    np.testing.assert_allclose(qd, qd_ref, rtol=0, atol=1e-12 * np.max(np.abs(qd_ref)))


def test_size_rule_and_product_grid():
    assert not HarmonicBalance(2, 64, 1, 264).structured
    assert HarmonicBalance(2, 512, 1, 2056).structured
    assert not HarmonicBalance(2, 512, 1, 2056, operator="dense").structured
    assert HarmonicBalance(1, 4, 1, 16, operator="structured").structured
    with pytest.raises(ValueError, match="operator"):
        HarmonicBalance(1, 4, 1, 16, operator="sparse")
    for harmonics in (1, 7, 64, 2048):
        assert product_samples(harmonics) > 4 * harmonics


def test_hill_on_dense_path_is_unchanged_by_solution_multipliers():
    model = gear("NLTV")
    sol = solve_periodic(model, rpm_to_rad_s(5000.0), harmonics=16, samples=72)
    hb = HarmonicBalance(model.ndof, 16, 1, 72)
    np.testing.assert_array_equal(solution_multipliers(sol), hill_multipliers(hb, sol.z, sol.omega_pinion,
                                                                              GearSystem(model)))


def test_starved_krylov_solves_end_in_a_convergence_error_not_a_wrong_answer(monkeypatch):
    """With GMRES allowed one product per step the structured Newton cannot reach the tolerance:
    solve_periodic raises ConvergenceError, naming the GMRES products, the residual reached."""
    import hbgear.engine.structured as structured_module
    from hbgear.errors import ConvergenceError

    monkeypatch.setattr(hb_module, "STRUCTURED_MIN_SIZE", 0)
    monkeypatch.setattr(structured_module, "MAX_PRODUCTS", 1)
    with pytest.raises(ConvergenceError, match="GMRES products") as error:
        solve_periodic(gear("NLTV"), rpm_to_rad_s(3000.0), harmonics=16, samples=72, max_iterations=5)
    assert "residual" in str(error.value)


# -- the continuation on the structured path (KrylovJacobian, bordered GMRES in the compiled corrector)


def test_gmres_solves_with_restarts_and_reports_when_it_does_not_converge():
    """:func:`~hbgear.engine.krylov.gmres` (compiled) solves to the asked relative residual with
    and without restarts, its converged flag read on the true residual; starved of products it
    says so and returns the best iterate with its true relative residual; a zero right-hand side
    is solved by zero with no product."""
    rng = np.random.default_rng(4)
    n = 120
    a = np.diag(np.linspace(1.0, 20.0, n)) + rng.normal(size=(n, n)) / np.sqrt(n)
    b = rng.normal(size=n)
    d = np.diag(a).copy()
    exact = np.linalg.solve(a, b)

    def run(b, rtol, restart, max_products, precondition=lambda v: v / d):
        solve = jax.jit(lambda b: gmres(lambda v: jnp.asarray(a) @ v, b, precondition=precondition, rtol=rtol,
                                        restart=restart, max_products=max_products))
        x, info = solve(jnp.asarray(b))
        return np.asarray(x), info

    for restart in (7, 200):
        x, info = run(b, 1e-11, restart, 2000)
        assert bool(info.converged) and np.linalg.norm(a @ x - b) <= 1e-11 * np.linalg.norm(b)
        np.testing.assert_allclose(x, exact, rtol=0, atol=1e-9 * np.max(np.abs(exact)))
    x_restarted, info_restarted = run(b, 1e-11, 7, 2000)
    _, info_full = run(b, 1e-11, 200, 2000)
    assert int(info_restarted.iterations) > int(info_full.iterations)  # restarts lose information
    x, info = run(b, 1e-14, 5, 10, precondition=lambda v: v)
    assert not bool(info.converged) and int(info.iterations) == 10
    assert float(info.relative_residual) == pytest.approx(np.linalg.norm(a @ x - b) / np.linalg.norm(b), rel=1e-9)
    x, info = run(np.zeros(n), 1e-10, 5, 10)
    assert bool(info.converged) and int(info.iterations) == 0 and not np.any(x)


@pytest.mark.parametrize("case", ["NLTV", "LTV"])
def test_krylov_jacobian_and_its_bordered_solve_are_the_dense_ones(case):
    """The continuation's form of the structured Jacobian: its matrix is the dense path's
    ``dR/dz`` (1e-10), ``scaled(sizes)`` is ``dR/dz diag(sizes)``, and the bordered solve by GMRES
    solves the dense bordered matrix to the tolerance it is given (:data:`BORDERED_RTOL`)."""
    model = gear(case)
    system, omega, harmonics, samples = GearSystem(model), rpm_to_rad_s(9000.0), 12, 56
    dense, structured = pair(model.ndof, harmonics, samples)
    rj_d, _, args_d = residual_functions(dense, system)
    rj_s, _, args_s = residual_functions(structured, system)
    z = solve_periodic(model, omega, harmonics=harmonics, samples=samples).z * 1.02
    r1, j1, p1 = (np.asarray(x) for x in rj_d(jnp.asarray(z), omega, *args_d))
    r2, jac, p2 = rj_s(jnp.asarray(z), omega, *args_s)
    assert isinstance(jac, KrylovJacobian)
    scale = np.max(np.abs(j1))
    np.testing.assert_allclose(np.asarray(jac.dense()), j1, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(np.asarray(r2), r1, rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.asarray(p2), p1, rtol=0, atol=1e-10 * np.max(np.abs(p1)))
    sizes = 1.0 + np.random.default_rng(7).random(dense.size) * 10
    np.testing.assert_allclose(np.asarray(jac.scaled(jnp.asarray(sizes)).dense()), j1 * sizes[None, :], rtol=0,
                               atol=1e-10 * scale * np.max(sizes))
    rng = np.random.default_rng(8)
    # a border row near the continuation's own (a unit tangent is mostly its p-component here)
    column, row, b = p1 * omega, np.append(0.1 * rng.normal(size=dense.size), 1.0), rng.normal(size=dense.size + 1)
    x = np.asarray(jax.jit(lambda j, c, r, b: j.bordered_factor(c, r).solve(b))(jac, column, row, b))
    bordered = np.block([[j1, column[:, None]], [row[None]]])
    assert np.linalg.norm(bordered @ x - b) <= 1.0001 * BORDERED_RTOL * np.linalg.norm(b)
    np.testing.assert_allclose(x, np.linalg.solve(bordered, b), rtol=0, atol=1e-7 * np.max(np.abs(x)))


def test_continuation_on_the_structured_path_is_the_dense_curve():
    """The compiled chord corrector with bordered GMRES solves (the structured path) follows the
    dense LU's curve -- the NLTV pair on its soft output spring, continued in the scaled unknowns
    of the arclength metric -- with the same iterations, the same parameters to 1e-10 and unknowns
    to 1e-9 (both converged to max|R| <= 1e-11 by different linear solves; the soft mode's
    conditioning, ~5e5, lets the unknowns differ by more than the residual), and each point
    solves the dense equations (residual within the tolerance)."""
    from hbgear.engine.continuation import continuation, sweep_method
    from hbgear.engine.metric import continuation_functions

    model = gear("NLTV")
    system, harmonics, samples = GearSystem(model), 8, 40
    p0, p1 = rpm_to_rad_s(6000.0), rpm_to_rad_s(6600.0)
    branches = []
    for hb in pair(model.ndof, harmonics, samples):
        rj, r, args, sizes = continuation_functions(hb, system, p0)
        assert sizes is not None  # the soft spring's mean in its own size
        branches.append(continuation(rj, r, np.zeros(hb.size), p0, p1, sweep_method(p0, p1, None), args=args,
                                     tolerance=1e-11, progress=False))
    theirs, ours = branches
    assert theirs.success and ours.success and len(ours.p) == len(theirs.p) > 10
    np.testing.assert_array_equal(ours.iterations, theirs.iterations)
    np.testing.assert_allclose(ours.p, theirs.p, rtol=1e-10)
    np.testing.assert_allclose(ours.z, theirs.z, rtol=0, atol=1e-9 * np.max(np.abs(theirs.z)))
    dense = pair(model.ndof, harmonics, samples)[0]
    sizes = continuation_functions(dense, system, p0)[3]
    for z, p in zip(ours.z[::5], ours.p[::5]):
        assert np.max(np.abs(np.asarray(dense.residual(jnp.asarray(z * sizes), p, system)))) <= 1e-11


@pytest.mark.parametrize("case, overrides, exact", [
    ("LTV, reaction output (a free mean slot)", ["friction.model='LTV'", "boundary.output='reaction'"], 1e-13),
    ("NLTV arctan", GEAR_CASES["NLTV"], 5e-9),  # 6.3e-10 here: the jump terms (left to GMRES)
])
def test_band_preconditioner_is_the_jacobians_band_and_solves_it(case, overrides, exact):
    """The preconditioner of the structured path (:mod:`hbgear.engine.banded`) written from the
    Fourier coefficients of the linearised force is the dense Jacobian's entries between
    harmonics at most ``BAND`` apart (to rounding where the Jacobian has no jump terms), zero
    elsewhere, and its block elimination solves it."""
    from hbgear.engine import banded

    model = build_model(load_config(EXAMPLE, overrides))
    system, omega, harmonics, samples = GearSystem(model), rpm_to_rad_s(9000.0), 12, 56
    dense, structured = pair(model.ndof, harmonics, samples)
    z = solve_periodic(model, omega, harmonics=harmonics, samples=samples).z * 1.02
    _, jac = dense.residual_and_linearization(jnp.asarray(z), omega, system)
    jac = np.asarray(jac)
    rj, _, args = residual_functions(structured, system)
    lin = rj(jnp.asarray(z), omega, *args)[1].linearization
    stiffness, damping = (np.fft.rfft(np.asarray(a), axis=-1)[..., : 2 * harmonics + 1] / a.shape[-1]
                          for a in (lin.stiffness, lin.damping))
    if lin.derivatives is not None:
        g = np.fft.rfft(np.asarray(lin.derivatives)[..., :samples], axis=-1)[..., : 2 * harmonics + 1] / samples
        damping = damping - g[-1]
        stiffness = stiffness - g[0] if g.shape[0] == 2 else stiffness
    blocks = banded.band_blocks(jnp.asarray(stiffness), jnp.asarray(damping), lin.w, lin.mass, lin.scale, harmonics,
                                system.free_mean_dof)
    band = np.asarray(banded.band_matrix(blocks, model.ndof, harmonics))
    order = np.tile(np.concatenate([[0], np.repeat(np.arange(1, harmonics + 1), 2)]), model.ndof)
    inside = np.abs(order[:, None] - order[None, :]) <= banded.BAND
    assert np.max(np.abs(band - np.where(inside, jac, 0.0))) <= exact * np.max(np.abs(jac))
    assert np.all(band[~inside] == 0.0)
    v = np.random.default_rng(9).normal(size=dense.size)
    x = np.asarray(banded.from_groups(banded.solve_band(banded.factor_band(blocks),
                                                        banded.to_groups(jnp.asarray(v), model.ndof, harmonics)),
                                      model.ndof, harmonics))
    assert np.max(np.abs(band @ x - v)) <= 1e-12 * np.max(np.abs(band)) * np.max(np.abs(x))


def test_structured_continuation_locates_the_dense_paths_folds():
    """Through turning points: the backlash pair (teeth separating, no friction: no jumps) from
    8000 rpm over its folds at ~11600, ~8787 and ~9194 rpm (H = 12) on the structured path (the
    bordered GMRES of the compiled corrector, its tangents for the fold location) as on the
    dense one: the same points, the same folds to 1e-9 of the speed."""
    from hbgear.engine.continuation import continuation, sweep_method
    from hbgear.engine.continuation.branch import PointKind
    from hbgear.engine.metric import continuation_functions

    model = build_model(load_config(Path(__file__).resolve().parents[1] / "examples" / "backlash.toml"))
    system, harmonics, samples = GearSystem(model), 12, 64
    p0, p1 = rpm_to_rad_s(8000.0), rpm_to_rad_s(12000.0)
    z0 = solve_periodic(model, p0, harmonics=harmonics, samples=samples).z
    branches = []
    for hb in pair(model.ndof, harmonics, samples):
        rj, r, args, sizes = continuation_functions(hb, system, p0)
        start = z0 if sizes is None else z0 / sizes
        branches.append(continuation(rj, r, start, p0, p1, sweep_method(p0, p1, None), args=args, tolerance=1e-10,
                                     progress=False, max_points=1000))
    theirs, ours = branches
    folds = [np.asarray(b.p)[np.asarray(b.kind) == PointKind.FOLD] for b in branches]
    assert len(folds[0]) == 3 and len(ours.p) == len(theirs.p)
    np.testing.assert_allclose(folds[1], folds[0], rtol=1e-9)
    np.testing.assert_allclose(ours.p, theirs.p, rtol=1e-9)


def test_linearization_holds_no_weakly_typed_scalars():
    """A linearisation traced in this process and one loaded from disk (exported programs return
    typed arrays) must give the Newton solve's kept program the same argument types, or every
    second process exports that program again (found: the base frequency and the scale were
    Python floats, weakly typed, when traced)."""
    model = gear("NLTV")
    system, omega = GearSystem(model), rpm_to_rad_s(9000.0)
    _, hb = pair(model.ndof, 8, 40)
    _, jac = hb.residual_and_linearization(jnp.zeros(hb.size), omega, system)
    weak = [jax.tree_util.keystr(path) for path, leaf in jax.tree_util.tree_flatten_with_path(jac.linearization)[0]
            if getattr(leaf, "weak_type", False)]
    assert weak == []
