"""What `hbgear frc` writes beside the curve: orders.csv / orders.png (DTE at mesh orders),
dynamic_factor.png (with the ISO 6336-1 resonance speed n_E1) and floquet.png (the multipliers of
a few selected points), each against an independent route:

- order amplitudes against the FFT of an independently solved point sampled on a fine grid, and
  the half orders of a ``nu = 2`` row against an independent ``nu = 2`` solve's harmonic table;
- n_E1 against a hand calculation from the pair's data, ISO's Eq. (30) for solid disks, and the
  primary resonance of a curve;
- the Floquet points against the stability column of frc.csv.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import hbgear
from hbgear.build import build_model
from hbgear.cli import main
from hbgear.config import load_config
from hbgear.gear.readouts import order_amplitudes
from hbgear.gear.resonance import iso6336_resonance
from hbgear.gear.response import COLUMNS, ORDER_KEY_COLUMNS, order_column

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "examples" / "paper_table1.toml"
BACKLASH = ROOT / "examples" / "backlash.toml"
ZONE = ["solver.harmonics=16", "solver.time_samples=256", "sweep.speed_rpm_start=8500", "sweep.speed_rpm_stop=9300"]
PD = ['boundary.output="torques"', "solver.harmonics=8", "solver.time_samples=256",
      "sweep.speed_rpm_start=29000", "sweep.speed_rpm_stop=27000"]


def _frc(out, config, sets, *extra):
    argv = ["frc", str(config), "--out", str(out), "--no-progress"]
    for s in sets:
        argv += ["--set", s]
    assert main(argv + list(extra)) == 0
    return out


def _csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def _fft_amplitudes_um(solution, orders, samples=512):
    """DTE amplitudes at mesh `orders` from ``state_at`` on `samples` points of the base period, by FFT."""
    q, _ = solution.state_at(np.arange(samples) / samples)
    spectrum = 2.0 * np.abs(np.fft.rfft(q[0])) / samples
    return 1e6 * spectrum[np.rint(np.asarray(orders) * solution.nu).astype(int)]


@pytest.fixture(scope="module")
def zone(tmp_path_factory):
    """LTV-A reference pair, H = 16, 8500 -> 9300 rpm: the parametric zone near 2 n_E1 / 3 with its
    two period doublings (exact monodromy)."""
    return _frc(tmp_path_factory.mktemp("zone"), PAPER, ZONE)


@pytest.fixture(scope="module")
def doubled(tmp_path_factory):
    """The backlash pair's period-doubled branch (as in test_frc_period_doubling.py)."""
    return _frc(tmp_path_factory.mktemp("doubled"), BACKLASH, PD)


def test_orders_csv_rows_follow_frc_csv_and_match_an_fft(zone):
    frc_header, frc_rows = _csv(zone / "frc.csv")
    header, rows = _csv(zone / "orders.csv")
    assert tuple(frc_header) == COLUMNS  # frc.csv keeps its columns
    assert header == [*ORDER_KEY_COLUMNS, *(f"dte_order_{k}_um" for k in range(1, 11))]  # K = min(16, 10)
    assert len(rows) == len(frc_rows)
    for i, (mine, theirs) in enumerate(zip(rows, frc_rows)):  # the same rows, as written in frc.csv
        assert mine[:4] == [str(i), theirs[0], theirs[1], theirs[COLUMNS.index("nu")]]

    model = build_model(load_config(PAPER))
    values = np.array(rows, dtype=float)
    for i in (5, len(rows) - 1):  # independent HB solves at two of the curve's speeds, sampled, FFT
        solution = hbgear.solve(model, speed_rpm=float(values[i, 1]), harmonics=16, stability=False)
        fft = _fft_amplitudes_um(solution, np.arange(1, 11))
        assert values[i, 4:] == pytest.approx(fft, rel=1e-8, abs=1e-9)
        assert values[i, 4] > 1.0 and values[i, 4] > 10 * values[i, 13]  # mesh order 1 dominates


def test_half_orders_of_a_nu2_row_match_an_independent_nu2_solve(doubled):
    from hbgear.gear.bifurcation import embed_subharmonic, half_order_indices, solve_period_doubled
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

    header, rows = _csv(doubled / "orders.csv")
    whole = [order_column(k) for k in range(1, 9)]  # H = 8: K = 8
    half = [order_column(k - 0.5) for k in range(1, 9)]
    assert header == [*ORDER_KEY_COLUMNS, *whole, *half]
    assert half[:2] == ["dte_order_0p5_um", "dte_order_1p5_um"]
    values = np.array(rows, dtype=float)
    nu = values[:, 3]
    assert np.any(nu == 1) and np.any(nu == 2)
    assert np.all(values[nu == 1, 12:] == 0.0)  # a one-mesh-period solution has no half orders

    last = values[-1]
    assert last[3] == 2 and last[1] == pytest.approx(27000.0)
    model = build_model(load_config(BACKLASH, ['boundary.output="torques"']))
    omega = rpm_to_rad_s(27000.0)  # independent nu = 2 solve, as in test_frc_period_doubling.py
    z0 = embed_subharmonic(solve_periodic(model, omega, harmonics=8, samples=256).z, model.ndof, 8, 16)
    z0[half_order_indices(model.ndof, 16)[:2]] = 2.0
    solution = solve_period_doubled(model, omega, z0, harmonics=16, samples=512)
    table = {order: amp for order, amp, _ in solution.harmonic_table()}
    expected = [table[k] for k in range(1, 9)] + [table[k - 0.5] for k in range(1, 9)]
    assert last[4:] == pytest.approx(expected, rel=1e-7, abs=1e-9)  # Newton tolerance 1e-9: measured 1e-8 at most
    assert last[header.index("dte_order_0p5_um")] > 5.0  # the teeth separate every other mesh period


def test_the_pictures_are_written(zone, doubled):
    for out in (zone, doubled):
        for name in ("frc.png", "orders.png", "dynamic_factor.png", "floquet.png"):
            assert (out / name).stat().st_size > 10_000, name


def test_floquet_points_follow_the_rule(zone):
    _, rows = _csv(zone / "frc.csv")
    curve = np.array(rows, dtype=float)
    stable, max_abs, p2p = (curve[:, COLUMNS.index(c)] for c in ("stable", "max_abs_floquet", "dte_p2p_um"))
    summary = json.loads((zone / "frc.json").read_text())
    points = summary["floquet_points"]
    picked = [p["row"] for p in points]
    assert 1 <= len(picked) <= 6 and len(set(picked)) == len(picked)
    assert [p["speed_rpm"] for p in points] == sorted(p["speed_rpm"] for p in points)
    reasons = {p["row"]: p["reason"] for p in points}
    assert reasons[int(np.argmax(max_abs))] == "most unstable"
    assert reasons[int(np.argmax(np.where(stable == 1, p2p, -np.inf)))] == "stable, largest DTE"
    crossings = summary["period_doubling"]
    assert len(crossings) == 2  # into and out of the zone
    for rec in crossings:  # each crossing: its unstable-side point is unstable in frc.csv, its other one stable
        i, j = rec["bracket_rows"]
        side = [r for r in (i, j) if "unstable side" in reasons.get(r, "")]
        assert len(side) == 1 and stable[side[0]] == 0 and stable[i + j - side[0]] == 1
    for p in points:
        assert p["max_abs_floquet"] == pytest.approx(max_abs[p["row"]], rel=1e-12)


def test_no_stability_skips_floquet_png_and_orders_count(tmp_path):
    sets = ["solver.harmonics=8", "solver.time_samples=64", "sweep.speed_rpm_start=12000",
            "sweep.speed_rpm_stop=12600", "sweep.orders=4"]
    out = _frc(tmp_path / "frc", PAPER, sets, "--no-stability")
    assert not (out / "floquet.png").exists() and not (out / "floquet.csv").exists()
    assert (out / "orders.png").stat().st_size > 0 and (out / "dynamic_factor.png").stat().st_size > 0
    header, _ = _csv(out / "orders.csv")
    assert header[4:] == [f"dte_order_{k}_um" for k in range(1, 5)]
    summary = json.loads((out / "frc.json").read_text())
    assert summary["floquet_points"] == [] and summary["orders"]["rule"] == "sweep.orders"


def test_orders_beyond_the_harmonics_are_bad_input(tmp_path, capsys):
    argv = ["frc", str(PAPER), "--out", str(tmp_path / "x"), "--set", "solver.harmonics=8", "--set", "sweep.orders=9"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "sweep.orders = 9" in err and "<= solver.harmonics / solver.subharmonic = 8" in err
    assert not (tmp_path / "x").exists()


def test_order_amplitudes_of_a_linear_read_out_with_rates():
    """A read-out ``x = w . q + v . q'`` (the form of a bearing force ``k y + c y'``) against the FFT of
    ``x(t)`` from ``state_at``; an order off the ``1/nu`` grid is exactly 0, one beyond ``H/nu`` refused."""
    model = build_model(load_config(PAPER))  # spring boundary: q = (delta, u)
    solution = hbgear.solve(model, speed_rpm=3000.0, harmonics=16, stability=False)
    w, v = np.array([2.0, -1.0]), np.array([0.0, 3e-5])
    n = 512
    q, qd = solution.state_at(np.arange(n) / n)
    fft = 2.0 * np.abs(np.fft.rfft(w @ q + v @ qd)) / n
    orders = np.arange(1, 17)
    got = order_amplitudes(solution.coefficients[None], 1, orders, weights=w, rate_weights=v,
                           base_frequency=solution.base_frequency)[0]
    assert got == pytest.approx(fft[orders], rel=1e-9, abs=1e-12 * fft.max())
    assert order_amplitudes(solution.coefficients[None], 1, [1.5])[0, 0] == 0.0
    with pytest.raises(ValueError, match="H/nu"):
        order_amplitudes(solution.coefficients[None], 1, [17])
    with pytest.raises(ValueError, match="base frequency"):
        order_amplitudes(solution.coefficients[None], 1, [1], rate_weights=v)


def test_n_e1_by_hand_for_the_reference_pair():
    """ISO 6336-1 Eq. (6) with Eq. (7) for the paper's pair, from its data (MODEL.md section 1)."""
    r = iso6336_resonance(build_model(load_config(PAPER)))
    module, zp, zg, phi, b_mm = 3.175e-3, 25, 31, math.radians(20.0), 20.0
    rbp, rbg = module * zp / 2 * math.cos(phi), module * zg / 2 * math.cos(phi)
    m1, m2 = 1.0594e-3 / rbp**2 / b_mm, 2.5047e-3 / rbg**2 / b_mm  # J / (b r_b^2) [kg/mm]
    m_red = m1 * m2 / (m1 + m2)
    c_gamma_alpha = 568.0 / b_mm  # 568 MN/m = 568 N/um, per mm of face
    n_e1 = 30000.0 / (math.pi * zp) * math.sqrt(c_gamma_alpha / m_red)
    assert r.m_red_kg_per_mm == pytest.approx(m_red, rel=1e-9)
    assert r.c_gamma_alpha_N_per_mm_um == pytest.approx(c_gamma_alpha, rel=1e-9)
    assert r.n_E1_rpm == pytest.approx(n_e1, rel=1e-9)
    assert 13390.0 < n_e1 < 13410.0  # 13,400 rpm: MODEL.md's completed Table 1
    # line load F_t / b at the (unshifted) pitch circle: 226 N m / 39.6875 mm / 20 mm = 285 N/mm >= 100
    assert r.line_load_N_per_mm == pytest.approx(226.0 / (module * zp / 2) / b_mm, rel=1e-9)
    assert r.N_S == 0.85
    assert r.main_resonance_rpm == pytest.approx((0.85 * n_e1, 1.15 * n_e1), rel=1e-12)
    assert r.intermediate_rpm == pytest.approx((1.15 * n_e1, 1.5 * n_e1), rel=1e-12)


def test_reduced_mass_is_iso_eq30_for_solid_disks_and_low_load_n_s():
    model = build_model(load_config(PAPER))
    rho, b = 7850.0, float(model.face_width_m)  # kg/m^3, m
    u = model.teeth_gear / model.teeth_pinion
    d_b1 = 2e3 * float(model.base_radius_pinion_m)  # mm
    d_m1 = 1.03 * d_b1  # any mean diameter: tip and root average
    disk = lambda d_mm: rho * math.pi * b * (1e-3 * d_mm) ** 4 / 32.0  # noqa: E731  J of a solid disk [kg m^2]
    solid = model.replace(inertia_pinion_kgm2=disk(d_m1), inertia_gear_kgm2=disk(u * d_m1))
    rho_mm = rho * 1e-9  # kg/mm^3
    eq30 = math.pi / 8.0 * (d_m1 / d_b1) ** 2 * d_m1**2 / (1.0 / rho_mm + 1.0 / (rho_mm * u**2))
    assert iso6336_resonance(solid).m_red_kg_per_mm == pytest.approx(eq30, rel=1e-12)
    light = iso6336_resonance(model.replace(torque_pinion_Nm=20.0))  # 25.2 N/mm < 100: Eq. (11)
    assert light.line_load_N_per_mm == pytest.approx(25.196850393700785, rel=1e-9)
    assert light.N_S == pytest.approx(0.5 + 0.35 * math.sqrt(light.line_load_N_per_mm / 100.0), rel=1e-15)
    assert light.n_E1_rpm == pytest.approx(iso6336_resonance(model).n_E1_rpm, rel=1e-15)


@pytest.fixture(scope="module")
def resonance_curve():
    model = build_model(load_config(PAPER))
    return hbgear.frequency_response(model, speed_rpm=(12500.0, 14200.0), harmonics=8, progress=False)


def test_n_e1_lies_at_the_primary_resonance(resonance_curve):
    """The mesh mode is excited at mesh order 1 when n = n_E1: the curve's DTE and dynamic-factor
    peaks land within 1 % of it, inside the main resonance range."""
    curve = resonance_curve
    r = curve.resonance
    for values in (curve.dte_p2p_um, curve.dynamic_factor):
        peak = float(curve.speed_rpm[int(np.argmax(values))])
        assert abs(peak / r.n_E1_rpm - 1.0) < 0.01
        assert r.main_resonance_rpm[0] < peak < r.main_resonance_rpm[1]


def test_floquet_points_take_folds_after_the_stable_peak(resonance_curve):
    """The rule's order on a curve without unstable points or crossings, two of its points marked
    as folds: the stable peak first, then the folds, within the limit."""
    from dataclasses import replace

    from hbgear.engine.continuation import PointKind

    curve = resonance_curve
    assert np.all(curve.stable == 1) and not curve.period_doublings
    kind = np.array(curve.response.branch.kind)
    kind[[10, 30]] = PointKind.FOLD
    folded = replace(curve, response=replace(curve.response, branch=replace(curve.response.branch, kind=kind)))
    peak = int(np.argmax(curve.dte_p2p_um))
    assert {p["row"]: p["reason"] for p in folded.floquet_points()} == {peak: "stable, largest DTE", 10: "fold",
                                                                         30: "fold"}
    assert [p["row"] for p in folded.floquet_points(limit=2)] == sorted([peak, 10], key=lambda i: curve.speed_rpm[i])
