"""hbgear.engine.continuation: pseudo-arclength continuation, folds, landing, statuses; `hbgear frc`.

Known answers: the Duffing oscillator ``x'' + 0.02 x' + x + 0.1 x^3 = 0.05 cos wt`` (its H=1
jump frequencies from the discriminant of the amplitude--frequency cubic, its backbone), a
linear oscillator (direct solves, closed form), and the reference gear pair (LTV, torques)
over its primary resonance against independent ``solve_periodic`` calls.
"""

import csv
import dataclasses
import json
import math
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

from hbgear import build_model, load_config
from hbgear.engine.continuation import Branch, PointKind, PseudoArclength, Status, continuation
from hbgear.engine.hb import HarmonicBalance
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
from hbgear.gear.system import GearSystem
from hbgear.engine.system import Duffing

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "paper_table1.toml"
C, K, A, F = 0.02, 1.0, 0.1, 0.05
DUFFING = Duffing(damping=C, stiffness=K, cubic=A, forcing=F)
HB1 = HarmonicBalance(1, 1, 1, 16)
HB7 = HarmonicBalance(1, 7, 1, 64)
GEAR_OVERRIDES = ["boundary.output='torques'", "friction.model='LTV'", "solver.harmonics=8", "solver.time_samples=64"]
HB_GEAR = HarmonicBalance(1, 8, 1, 64)


def problem(hb, system):
    def rj(z, p):
        return hb.residual_and_jacobians(jnp.asarray(z), p, system)

    def r(z, p):
        return hb.residual(jnp.asarray(z), p, system)

    return rj, r


def analytic_folds(c=C, k=K, a=A, f=F, lo=0.5, hi=2.0):
    """Jump frequencies of the H=1 relation ``((k - w^2 + 3/4 a A^2)^2 + (c w)^2) A^2 = f^2``:
    where the cubic in ``u = A^2`` has a double root (zero discriminant)."""
    b = 0.75 * a

    def disc(w):
        d = k - w * w
        c3, c2, c1, c0 = b * b, 2 * d * b, d * d + c * c * w * w, -f * f
        return 18 * c3 * c2 * c1 * c0 - 4 * c2**3 * c0 + c2**2 * c1**2 - 4 * c3 * c1**3 - 27 * c3**2 * c0**2

    w = np.linspace(lo, hi, 3001)
    sign = np.sign(disc(w))
    return sorted(brentq(disc, w[i], w[i + 1], xtol=1e-15, rtol=1e-15) for i in np.flatnonzero(np.diff(sign)))


def fundamental(branch):
    return np.hypot(branch.z[:, 1], branch.z[:, 2])


@pytest.fixture(scope="module")
def duffing_h1():
    return continuation(*problem(HB1, DUFFING), np.zeros(HB1.size), 0.5, 2.0, PseudoArclength(), tolerance=1e-12, max_points=2000)


@pytest.fixture(scope="module")
def duffing_h7():
    return continuation(*problem(HB7, DUFFING), np.zeros(HB7.size), 0.5, 2.0, PseudoArclength(), tolerance=1e-10, max_points=2000)


# ---------------------------------------------------------------------------- (a) Duffing


def test_duffing_passes_both_folds(duffing_h1, duffing_h7):
    for branch in (duffing_h1, duffing_h7):
        assert branch.status == Status.SUCCESS, branch.message
        assert branch.p[0] == 0.5 and branch.p[-1] == 2.0  # lands exactly on p_end
        assert branch.kind[0] == PointKind.START and branch.kind[-1] == PointKind.END
        assert len(branch.folds) == 2
        steps = np.diff(branch.p)
        assert np.any(steps < 0)  # the path goes back in w between the folds
        # the tangent's p-component is + before the first fold, - between, + after
        f1, f2 = branch.folds
        assert np.all(branch.tangent_p[:f1] > 0) and np.all(branch.tangent_p[f1 + 1 : f2] < 0)
        assert np.all(branch.tangent_p[f2 + 1 :] > 0)
        assert np.all(np.abs(branch.tangent_p[branch.folds]) < 1e-8)


def test_duffing_fold_frequencies_match_analytic(duffing_h1, duffing_h7):
    low, high = analytic_folds()
    assert 1.0 < low < high < 1.3
    upper, lower = duffing_h1.fold_p  # path order: the upper (jump-down) fold comes first
    assert upper == pytest.approx(high, rel=1e-6)
    assert lower == pytest.approx(low, rel=1e-6)
    upper7, lower7 = duffing_h7.fold_p
    assert upper7 == pytest.approx(high, rel=1e-2)
    assert lower7 == pytest.approx(low, rel=1e-2)
    assert np.max(duffing_h1.residual) <= 1e-12 and np.max(duffing_h7.residual) <= 1e-10


def test_duffing_peak_on_backbone(duffing_h1, duffing_h7):
    for branch in (duffing_h1, duffing_h7):
        amp = fundamental(branch)
        i = int(np.argmax(amp))
        backbone = math.sqrt(K + 0.75 * A * amp[i] ** 2)
        assert branch.p[i] == pytest.approx(backbone, rel=1e-2)
        # the peak lies between the two folds on the upper branch, amplitude ~ f / (c w)
        assert amp[i] == pytest.approx(F / (C * branch.p[i]), rel=2e-2)


def test_reverse_direction_finds_the_same_folds(duffing_h1):
    back = continuation(*problem(HB1, DUFFING), np.zeros(HB1.size), 2.0, 0.5, PseudoArclength(), tolerance=1e-12, max_points=2000)
    assert back.status == Status.SUCCESS and back.p[-1] == 0.5
    assert np.sort(back.fold_p) == pytest.approx(np.sort(duffing_h1.fold_p), rel=1e-9)


# ---------------------------------------------------------------------------- (b) linear


def test_linear_oscillator_matches_direct_solves():
    linear = Duffing(damping=C, stiffness=K, cubic=0.0, forcing=F)
    rj, r = problem(HB7, linear)
    branch = continuation(rj, r, np.zeros(HB7.size), 0.5, 2.0, PseudoArclength(), tolerance=1e-12, max_points=2000)
    assert branch.status == Status.SUCCESS and len(branch.folds) == 0
    assert np.all(np.diff(branch.p) > 0)
    for p, z in zip(branch.p[::7], branch.z[::7]):
        r0, jz, _ = rj(np.zeros(HB7.size), float(p))
        direct = np.linalg.solve(np.asarray(jz), -np.asarray(r0))
        assert np.max(np.abs(z - direct)) <= 1e-10
    amp = fundamental(branch)
    closed = F / np.hypot(K - branch.p**2, C * branch.p)
    assert np.max(np.abs(amp - closed) / closed) < 1e-10
    assert np.max(np.abs(branch.z[:, 3:])) < 1e-12  # no higher harmonics


# ---------------------------------------------------------------------------- generic behaviour


def test_circle_fold_and_turning_back():
    """``z^2 + p^2 = 1`` from p = 0 towards 2: fold at p = 1, then the branch turns back past 0."""

    def rj(z, p):
        return np.array([z[0] ** 2 + p**2 - 1]), np.array([[2 * z[0]]]), np.array([2 * p])

    def r(z, p):
        return np.array([z[0] ** 2 + p**2 - 1])

    branch = continuation(rj, r, [0.9], 0.0, 2.0, PseudoArclength(ds=0.05, ds_max=0.1, parameter_scale=1.0), tolerance=1e-13)
    assert branch.status == Status.TURNED_BACK
    assert "turned back" in branch.message
    assert branch.fold_p == pytest.approx([1.0], abs=1e-12)
    assert branch.p[-1] < 0
    assert np.all(np.abs(branch.z[:, 0] ** 2 + branch.p**2 - 1) <= 1e-13)


def test_failure_is_a_status_with_a_message():
    def rj(z, p):
        bad = np.nan if p > 1.0 else 0.0
        return np.array([z[0] - p + bad]), np.eye(1), np.array([-1.0])

    def r(z, p):
        return rj(z, p)[0]

    branch = continuation(rj, r, [0.0], 0.0, 2.0, PseudoArclength(ds=0.1, ds_min=1e-6, ds_max=0.2, parameter_scale=1.0))
    assert branch.status == Status.STEP_TOO_SMALL and not branch.success
    assert "stuck at p = 1" in branch.message and "non-finite" in branch.message
    assert branch.p[-1] <= 1.0 and branch.p[-1] > 1.0 - 1e-5  # no silent gap: it got as close as ds_min allows
    assert np.all(np.isfinite(branch.residual))

    capped = continuation(rj, r, [0.0], 0.0, 0.9, PseudoArclength(ds=0.01, ds_max=0.01, parameter_scale=1.0), max_points=5)
    assert capped.status == Status.MAX_POINTS and len(capped) == 5

    stopped = continuation(rj, r, [0.0], 0.0, 0.9, PseudoArclength(parameter_scale=1.0), callback=lambda p, z: p > 0.3)
    assert stopped.status == Status.STOPPED and 0.3 < stopped.p[-1] < 0.9


def test_options_and_branch_are_checked_and_immutable(duffing_h1):
    with pytest.raises(ValueError):
        PseudoArclength(ds=1.0, ds_max=0.1)
    with pytest.raises(ValueError):
        PseudoArclength(target_iterations=20, max_corrector_iterations=10)
    with pytest.raises(ValueError):
        PseudoArclength(max_angle_deg=120)
    assert isinstance(duffing_h1, Branch)
    with pytest.raises(ValueError):
        duffing_h1.p[0] = 1.0
    n = len(duffing_h1)
    assert duffing_h1.z.shape == (n, HB1.size)
    for name in ("kind", "iterations", "residual", "tangent_p", "ds"):
        assert getattr(duffing_h1, name).shape == (n,)


# ---------------------------------------------------------------------------- (c) gear pair


@pytest.fixture(scope="module")
def gear():
    cfg = load_config(EXAMPLE, GEAR_OVERRIDES)
    model = build_model(cfg)
    assert model.is_linear and model.ndof == 1
    w0, w1 = rpm_to_rad_s(12000.0), rpm_to_rad_s(15000.0)
    start = solve_periodic(model, w0, harmonics=8, samples=64, tolerance=1e-12)
    from hbgear.engine.hb import residual_functions
    from hbgear.engine.continuation import sweep_method

    rj, r, fixed = residual_functions(HB_GEAR, GearSystem(model))
    with warnings.catch_warnings():  # compiled, not the Python corrector after a failed trace
        warnings.simplefilter("error", RuntimeWarning)
        branch = continuation(rj, r, start.z, w0, w1, sweep_method(w0, w1), tolerance=1e-12, max_points=4000,
                              args=fixed)
    return model, branch


def test_gear_primary_resonance_matches_solve_periodic(gear):
    model, branch = gear
    assert branch.status == Status.SUCCESS, branch.message
    assert np.max(branch.residual) <= 1e-12
    assert len(branch.folds) == 0 and np.all(np.diff(branch.p) > 0)  # LTV: linear, no folds
    amp = fundamental(branch)
    peak = int(np.argmax(amp))
    assert 12500 < branch.p[peak] * 30 / np.pi < 14500  # the primary resonance is inside
    for i in sorted({1, peak - 3, peak, peak + 5, len(branch) // 2, len(branch) - 1}):
        reference = solve_periodic(model, float(branch.p[i]), harmonics=8, samples=64, tolerance=1e-12)
        scale = np.max(np.abs(reference.z))
        assert np.max(np.abs(branch.z[i] - reference.z)) <= 1e-8 * scale


def test_frc_command_writes_the_curve(tmp_path, gear):
    from hbgear import cli

    out = tmp_path / "frc"
    args = ["frc", str(EXAMPLE), "--out", str(out), "--no-progress"]
    for item in GEAR_OVERRIDES + ["sweep.speed_rpm_start=15000", "sweep.speed_rpm_stop=12000"]:
        args += ["--set", item]
    assert cli.main(args) == 0
    with open(out / "frc.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["speed_rpm", "mesh_freq_hz", "dte_mean_um", "dte_rms_um", "dte_p2p_um", "dynamic_factor",
                       "max_abs_floquet", "stable", "nu", "residual"]
    data = np.array(rows[1:], dtype=float)
    assert data[0, 0] == pytest.approx(15000.0, rel=1e-14) and data[-1, 0] == pytest.approx(12000.0, rel=1e-14)
    assert np.all(np.diff(data[:, 0]) < 0)
    assert data[:, 1] == pytest.approx(data[:, 0] / 60 * 25, rel=1e-12)
    assert np.all(data[:, 9] <= 1e-9) and np.all(data[:, 8] == 1)
    summary = json.loads((out / "frc.json").read_text())
    assert summary["status"] == "success" and summary["points"] == len(data) and summary["harmonics"] == 8
    assert summary["folds"] == [] and "timings_s" in summary and "config" in summary
    if summary["stability"]["available"]:
        assert set(np.unique(data[:, 7])) <= {0.0, 1.0}
        assert np.all(data[:, 6] > 0)
    assert (out / "frc.png").stat().st_size > 1000


def test_jit_step_traces_closures_that_fill_caches_on_their_first_call():
    """HarmonicBalance builds its quadrature on the first eager call; a closure over a fresh
    instance must still run compiled (no fall-back warning), with the start compiled too."""
    fresh = HarmonicBalance(1, 7, 1, 66)  # its own caches: nothing computed for it yet
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        branch = continuation(*problem(fresh, DUFFING), np.zeros(fresh.size), 0.5, 2.0,
                              PseudoArclength(jit_step=True), tolerance=1e-10, max_points=2000)
    assert branch.status == Status.SUCCESS, branch.message
    assert len(branch.folds) == 2


def test_compiled_corrector_takes_the_gear_pair_as_arguments(gear):
    """A second gear pair through the same functions reuses the compiled program (the model's
    parameters are arguments of it, not constants) and gets its own curve, equal to the Python
    corrector's; its start, corrected from `start_guess` inside the compiled corrector, is
    solve_periodic's solution. Stale constants would give the first pair's curve."""
    from hbgear.engine.hb import residual_functions
    from hbgear.engine.continuation import sweep_method
    from hbgear.engine.continuation import _JIT_CACHE
    from hbgear.gear.solve import start_guess

    model, first = gear
    other = model.replace(torque_pinion_Nm=1.7 * model.torque_pinion_Nm, damping_ratio=1.5 * model.damping_ratio)
    w0, w1 = rpm_to_rad_s(12000.0), rpm_to_rad_s(15000.0)
    rj, r, fixed = residual_functions(HB_GEAR, GearSystem(other))
    assert rj is residual_functions(HB_GEAR, GearSystem(model))[0]
    compiled = _JIT_CACHE[(rj, r, HB_GEAR.size)][0]
    programs = compiled._cache_size()
    guess = start_guess(other, HB_GEAR, GearSystem(other))
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        branch = continuation(rj, r, guess, w0, w1, sweep_method(w0, w1), tolerance=1e-12, max_points=4000,
                              args=fixed)
    assert compiled._cache_size() == programs  # no new trace for the new pair
    assert branch.status == Status.SUCCESS, branch.message
    start = solve_periodic(other, w0, harmonics=8, samples=64, tolerance=1e-12)
    assert np.max(np.abs(branch.z[0] - start.z)) <= 1e-9 * np.max(np.abs(start.z))
    python = continuation(rj, r, start.z, w0, w1, dataclasses.replace(sweep_method(w0, w1), jit_step=False, chord=False),
                          tolerance=1e-12, max_points=4000, args=fixed)
    assert len(branch) == len(python)
    np.testing.assert_allclose(branch.p, python.p, rtol=1e-9)
    np.testing.assert_allclose(branch.z, python.z, atol=1e-8 * np.max(np.abs(python.z)))
    assert np.max(fundamental(branch)) < 0.8 * np.max(fundamental(first))  # more damping: a lower peak


def test_frc_falls_back_to_solve_periodic_when_the_start_guess_fails(tmp_path, monkeypatch):
    """A start guess Newton cannot use (NaN here) costs only the detour: the curve is the same as
    from the regular guess, started from solve_periodic's staged start."""
    import hbgear.gear.response as frc_module
    from hbgear import cli

    def run(out):
        args = ["frc", str(EXAMPLE), "--out", str(out), "--no-progress", "--no-stability", "--no-period-doubling"]
        for item in GEAR_OVERRIDES + ["sweep.speed_rpm_start=12000", "sweep.speed_rpm_stop=13000"]:
            args += ["--set", item]
        assert cli.main(args) == 0
        return np.loadtxt(out / "frc.csv", delimiter=",", skiprows=1)

    regular = run(tmp_path / "regular")
    monkeypatch.setattr(frc_module, "start_guess", lambda model, hb, system: np.full(hb.size, np.nan))
    detour = run(tmp_path / "detour")
    assert detour.shape == regular.shape
    np.testing.assert_allclose(detour[:, :6], regular[:, :6], rtol=1e-9)


# ---------------------------------------------------------------------------- jit_step


def test_jit_step_gives_the_same_branch(duffing_h7):
    """The compiled corrector is the same algorithm: same steps, same points to rounding."""
    jitted = continuation(*problem(HB7, DUFFING), np.zeros(HB7.size), 0.5, 2.0, PseudoArclength(jit_step=True),
                          tolerance=1e-10, max_points=2000)
    assert jitted.status == Status.SUCCESS, jitted.message
    assert len(jitted) == len(duffing_h7) and np.array_equal(jitted.kind, duffing_h7.kind)
    assert np.array_equal(jitted.iterations, duffing_h7.iterations)
    assert np.max(np.abs(jitted.z - duffing_h7.z)) <= 1e-10
    assert np.max(np.abs(jitted.p - duffing_h7.p)) <= 1e-10
    assert np.max(np.abs(jitted.tangent_p - duffing_h7.tangent_p)) <= 1e-10
    assert jitted.fold_p == pytest.approx(duffing_h7.fold_p, rel=1e-10)
    assert np.max(jitted.residual) <= 1e-10


def test_jit_step_failures_and_fallback():
    def rj(z, p):  # traceable, non-finite beyond p = 1
        bad = jnp.where(p > 1.0, jnp.nan, 0.0)
        return jnp.stack([z[0] - p + bad]), jnp.eye(1), jnp.array([-1.0])

    def r(z, p):
        return rj(z, p)[0]

    opts = dict(ds=0.1, ds_min=1e-6, ds_max=0.2, parameter_scale=1.0)
    jitted = continuation(rj, r, [0.0], 0.0, 2.0, PseudoArclength(**opts, jit_step=True))
    python = continuation(rj, r, [0.0], 0.0, 2.0, PseudoArclength(**opts))
    assert jitted.status == python.status == Status.STEP_TOO_SMALL
    assert "non-finite" in jitted.message and jitted.message == python.message
    # the same steps; the compiled segment forms y + ds t in XLA (1 ulp from numpy's rounding)
    assert len(jitted) == len(python) and np.max(np.abs(jitted.p - python.p)) <= 1e-15

    def circle_rj(z, p):  # numpy only: jit_step falls back to the Python corrector
        return np.array([z[0] ** 2 + p**2 - 1]), np.array([[2 * z[0]]]), np.array([2 * p])

    def circle_r(z, p):
        return np.array([z[0] ** 2 + p**2 - 1])

    opts = dict(ds=0.05, ds_max=0.1, parameter_scale=1.0)
    with pytest.warns(RuntimeWarning, match="jit_step"):
        fallback = continuation(circle_rj, circle_r, [0.9], 0.0, 2.0, PseudoArclength(**opts, jit_step=True), tolerance=1e-13)
    plain = continuation(circle_rj, circle_r, [0.9], 0.0, 2.0, PseudoArclength(**opts), tolerance=1e-13)
    assert fallback.status == plain.status == Status.TURNED_BACK
    assert np.array_equal(fallback.z, plain.z) and np.array_equal(fallback.p, plain.p)


def _correctors(hb, system, scale):
    from hbgear.engine.continuation import _jit_corrector, _python_corrector

    rj, r = problem(hb, system)
    compiled = _jit_corrector(rj, r, hb.size)
    return _python_corrector(rj, r, scale, hb.size), compiled


def test_compiled_chord_step_equals_the_python_newton_corrector(duffing_h7):
    """From the same predictor, the chord corrector (LU of the previous point, Sherman--Morrison
    for the new border row) lands on the Python Newton corrector's point, with its tangent; a
    factorisation from far away fails to contract and the Newton restart still lands there."""
    from hbgear.engine.continuation import _Compiled

    scale = 2.0
    python, compiled = _correctors(HB7, DUFFING, scale)
    i = len(duffing_h7) // 3
    y0 = np.append(duffing_h7.z[i], duffing_h7.p[i] / scale)
    y1 = np.append(duffing_h7.z[i + 1], duffing_h7.p[i + 1] / scale)
    chord = _Compiled(compiled, chord=True, scale=scale)
    secant = (y1 - y0) / np.linalg.norm(y1 - y0)
    at_y0 = chord(y0, secant, secant @ y0, secant, 0, np.inf)  # converged at once: tangent + LU at y0
    t = at_y0.tangent
    np.testing.assert_allclose(t, python(y0, secant, secant @ y0, secant, 0, np.inf).tangent, atol=1e-12)
    y_pred = y0 + 1.5 * np.linalg.norm(y1 - y0) * t
    ref = python(y_pred, t, t @ y_pred, t, 10, 1e-11)
    got = chord(y_pred, t, t @ y_pred, t, 10, 1e-11)
    assert got.iterations >= 1 and got.r_norm <= 1e-11
    np.testing.assert_allclose(got.y, ref.y, atol=1e-10)
    np.testing.assert_allclose(got.tangent, ref.tangent, atol=1e-9)

    far = _Compiled(compiled, chord=True, scale=scale)
    y_far = np.append(duffing_h7.z[-1], duffing_h7.p[-1] / scale)
    far(y_far, secant, secant @ y_far, secant, 0, np.inf)  # keeps the LU of the last point
    restarted = far(y_pred, t, t @ y_pred, t, 10, 1e-11)
    assert restarted.iterations > ref.iterations  # the chord steps tried count too
    np.testing.assert_allclose(restarted.y, ref.y, atol=1e-10)


def test_chord_branch_matches_the_newton_branch(duffing_h7):
    """The whole branch with the compiled chord corrector: same folds and end point to the tolerance."""
    chord = continuation(*problem(HB7, DUFFING), np.zeros(HB7.size), 0.5, 2.0,
                         PseudoArclength(jit_step=True, chord=True), tolerance=1e-10, max_points=2000)
    assert chord.status == Status.SUCCESS, chord.message
    assert np.max(chord.residual) <= 1e-10
    assert len(chord.folds) == len(duffing_h7.folds) == 2
    assert chord.fold_p == pytest.approx(duffing_h7.fold_p, rel=1e-8)
    np.testing.assert_allclose(chord.z[-1], duffing_h7.z[-1], atol=1e-9)
    np.testing.assert_allclose(chord.z[chord.folds], duffing_h7.z[duffing_h7.folds], atol=1e-6)


def test_step_control_counts_a_chord_iteration_as_half_a_newton_iteration(duffing_h7):
    """The step-size control counts work (Newton iterations + half the chord iterations), so the
    chord corrector's slower, linear convergence does not shrink the steps: its branch has about
    as many points as the Newton corrector's (counting chord iterations as Newton ones gave
    ~2.7x as many on this curve)."""
    from hbgear.engine.continuation import CHORD_ITERATION_WORK, _Compiled

    scale = 2.0
    python, compiled = _correctors(HB7, DUFFING, scale)
    i = len(duffing_h7) // 3
    y0, y1 = (np.append(duffing_h7.z[j], duffing_h7.p[j] / scale) for j in (i, i + 1))
    secant = (y1 - y0) / np.linalg.norm(y1 - y0)
    chord = _Compiled(compiled, chord=True, scale=scale)
    t = chord(y0, secant, secant @ y0, secant, 0, np.inf).tangent
    y_pred = y0 + 1.5 * np.linalg.norm(y1 - y0) * t
    got = chord(y_pred, t, t @ y_pred, t, 10, 1e-11)  # chord steps only
    assert got.iterations >= 2 and got.work == CHORD_ITERATION_WORK * got.iterations
    ref = python(y_pred, t, t @ y_pred, t, 10, 1e-11)
    assert ref.work == ref.iterations

    options = dict(tolerance=1e-10, max_points=2000)
    newton_branch = continuation(*problem(HB7, DUFFING), np.zeros(HB7.size), 0.5, 2.0,
                                 PseudoArclength(jit_step=True), **options)
    chord_branch = continuation(*problem(HB7, DUFFING), np.zeros(HB7.size), 0.5, 2.0,
                                PseudoArclength(jit_step=True, chord=True), **options)
    assert newton_branch.status == chord_branch.status == Status.SUCCESS
    assert len(chord_branch) <= 1.2 * len(newton_branch)


@pytest.mark.filterwarnings("ignore::RuntimeWarning", "ignore::scipy.linalg.LinAlgWarning")
def test_compiled_line_search_equals_the_python_corrector():
    """Newton on atan(5 z) = 0.3 overshoots from |5 z| > 1.4: the backtracking line search runs.
    The compiled corrector (its line search as loop turns) lands where the Python one does,
    with the same iteration counts, and fails the same way where both fail."""
    from hbgear.engine.continuation import _Compiled, _jit_corrector, _python_corrector

    def rj(z, p):
        return jnp.stack([jnp.arctan(5 * z[0]) - 0.3 * p]), jnp.array([[5 / (1 + 25 * z[0] ** 2)]]), jnp.array([-0.3])

    def r(z, p):
        return rj(z, p)[0]

    python = _python_corrector(rj, r, 1.0, 1)
    compiled = _Compiled(_jit_corrector(rj, r, 1), chord=False, scale=1.0)
    row = np.array([0.0, 1.0])
    for z0 in (0.6, 0.8, 1.3, -0.6):
        y = np.array([z0, 1.0])
        a, b = python(y, row, 1.0, row, 20, 1e-12), compiled(y, row, 1.0, row, 20, 1e-12)
        assert type(a) is type(b) and a.iterations == b.iterations
        if hasattr(a, "y"):
            assert a.iterations >= 4 and abs(b.y[0] - np.tan(0.3) / 5) <= 1e-12
        else:
            assert a.reason == b.reason


def test_formulation_b_on_the_spring_does_not_crawl():
    """LTV-B on the soft output spring: the mean friction torque follows the response and the
    spring's mean wind-up follows it ``spring_stiffness_ratio`` (5e5) times more than the mesh.
    Counted in units of the spring's force (``GearSystem.arclength_mean_scales``) it no longer
    fills the arclength: 1000 -> 1100 rpm at H = 32 in 175 points (before: 1000 points reached
    1020.5 rpm; at H = 8 neither crawls), and the points are the solutions of ``solve_periodic``
    at their speeds (only the metric changed). The linear LTV-A model keeps the plain metric."""
    from hbgear.gear.response import frequency_response

    model = build_model(load_config(EXAMPLE, ["friction.formulation='B'"]))
    system = GearSystem(model)
    assert not model.is_linear and system.arclength_mean_scales(1.0) is not None
    assert GearSystem(build_model(load_config(EXAMPLE))).arclength_mean_scales(1.0) is None
    curve = frequency_response(model, rpm_to_rad_s(1000.0), rpm_to_rad_s(1100.0), harmonics=32, samples=1024,
                               max_points=400, stability=False, progress=False)
    assert curve.success, curve.response.message
    assert curve.points < 250, curve.points
    response = curve.response
    for i in (len(response) // 3, len(response) - 2):
        reference = solve_periodic(model, float(response.parameter[i]), harmonics=32, samples=1024, tolerance=1e-12)
        assert np.max(np.abs(response.z[i] - reference.z)) <= 1e-7 * np.max(np.abs(reference.z))


def test_solve_at_parameter_reuses_the_curves_compiled_corrector():
    """A fixed-parameter solve by the corrector of a compiled continuation of the same functions
    (as the period-doubling search does): the solution of the engine's Newton on the same
    equations (1e-10), and no program compiled for it -- neither a new trace of the corrector
    nor the separately compiled residual functions."""
    from hbgear.engine.continuation import solve_at_parameter
    from hbgear.engine.continuation.compiled import _cached_jit_corrector
    from hbgear.engine.hb import residual_functions
    from hbgear.engine.newton import newton

    hb = HarmonicBalance(1, 5, 1, 32)
    rj, r, fixed = residual_functions(hb, DUFFING)
    branch = continuation(rj, r, np.zeros(hb.size), 0.5, 2.0, PseudoArclength(jit_step=True, chord=True),
                          tolerance=1e-11, max_points=2000, args=fixed)
    assert branch.status == Status.SUCCESS, branch.message
    advance = _cached_jit_corrector(rj, r, hb.size)[0]
    programs = (advance._cache_size(), HarmonicBalance._residual_jit._cache_size(),
                HarmonicBalance._residual_and_jacobians_jit._cache_size())
    k = len(branch) // 2
    p = 0.5 * (branch.p[k] + branch.p[k + 1])
    ours = solve_at_parameter(rj, r, branch.z[k], p, args=fixed, tolerance=1e-11)
    assert (advance._cache_size(), HarmonicBalance._residual_jit._cache_size(),
            HarmonicBalance._residual_and_jacobians_jit._cache_size()) == programs
    reference = newton(lambda z: hb.residual_and_jacobians(jnp.asarray(z), p, DUFFING)[:2],
                       lambda z: hb.residual(jnp.asarray(z), p, DUFFING), branch.z[k], tolerance=1e-12)
    assert ours.converged and reference.converged
    assert ours.residual_norm <= 1e-11
    np.testing.assert_allclose(ours.z, reference.z, rtol=0, atol=1e-10 * np.max(np.abs(reference.z)))
