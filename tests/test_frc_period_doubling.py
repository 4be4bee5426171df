"""`hbgear frc` follows period-doubled (nu = 2) branches (hbgear.cli.frc).

The backlash pair of ``examples/backlash.toml`` reduced to the DTE alone (boundary "torques",
no friction, zeta 0.05), swept 29,000 -> 27,000 rpm with H = 8: the upper edge of the
parametric tongue (a multiplier crosses -1 at ~28,190 rpm) lies inside the sweep, the nu = 1
solution below it is unstable, and the period-doubled branch (bounded by contact loss) exists
down to the end of the sweep. Its DTE is checked against time integration (an independent route)
and against an independent nu = 2 harmonic-balance solve.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hbgear.gear.bifurcation import embed_subharmonic, half_order_indices, solve_period_doubled
from hbgear.build import build_model
from hbgear.cli import main
from hbgear.cli.frc import period_doubling_enabled
from hbgear.gear.response import COLUMNS, PD_AUTO_MAX_UNKNOWNS
from hbgear.config import load_config
from hbgear.gear.simulate import simulate
from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "backlash.toml"
SETS = ['boundary.output="torques"', "solver.harmonics=8", "solver.time_samples=256",
        "sweep.speed_rpm_start=29000", "sweep.speed_rpm_stop=27000"]


def _run(out, *extra):
    argv = ["frc", str(EXAMPLE), "--out", str(out), "--no-progress"]
    for s in SETS:
        argv += ["--set", s]
    assert main(argv + list(extra)) == 0
    with open(out / "frc.csv", newline="") as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    header, body = rows[0], np.array([[float(x) for x in r] for r in rows[1:]])
    return header, body, json.loads((out / "frc.json").read_text())


@pytest.fixture(scope="module")
def frc(tmp_path_factory):
    return _run(tmp_path_factory.mktemp("frc_pd"))


def test_nu2_branch_rows_and_record(frc):
    header, body, summary = frc
    assert tuple(header) == COLUMNS
    nu = body[:, COLUMNS.index("nu")]
    n1 = int(np.sum(nu == 1))
    assert n1 > 20 and np.all(nu[:n1] == 1) and np.all(nu[n1:] == 2)  # nu = 2 rows after the nu = 1 rows
    assert summary["points"] == n1

    records = summary["period_doubling"]
    assert len(records) == 1, records
    rec = records[0]
    assert 28100.0 < rec["speed_rpm"] < 28300.0
    assert rec["multiplier"] == pytest.approx(-1.0, abs=1e-4)
    assert rec["unstable_side"] == "below"
    assert rec["status"] == "reached sweep end", rec["message"]
    assert rec["points"] == len(body) - n1 and rec["first_row"] == n1

    two = body[n1:]
    speed2 = two[:, 0]
    assert speed2[-1] == pytest.approx(27000.0, abs=1e-6)  # followed to the end of the sweep
    assert np.all((speed2 >= 27000.0 - 1e-6) & (speed2 <= rec["speed_rpm"] + 20.0))
    assert np.all(two[:, COLUMNS.index("residual")] < 1e-8)
    # the branch grows away from the nu = 1 curve: at 27,000 rpm the teeth separate
    p2p = COLUMNS.index("dte_p2p_um")
    one_end = body[:n1][np.argmin(np.abs(body[:n1, 0] - 27000.0)), p2p]
    assert two[-1, p2p] > 10.0 * one_end
    # where the teeth separate the nu = 2 branch is the attractor (TI below converges to it)
    far = speed2 < rec["speed_rpm"] - 200.0
    assert np.any(far) and np.all(two[far, COLUMNS.index("stable")] == 1)


def test_nu1_unstable_below_the_crossing(frc):
    _, body, summary = frc
    rec = summary["period_doubling"][0]
    one = body[body[:, COLUMNS.index("nu")] == 1]
    stable = one[:, COLUMNS.index("stable")]
    floq = one[:, COLUMNS.index("max_abs_floquet")]
    below = one[:, 0] < rec["speed_rpm"] - 5.0
    above = one[:, 0] > rec["speed_rpm"] + 5.0
    assert np.sum(below) > 10 and np.sum(above) > 10
    assert np.all(stable[below] == 0) and np.all(floq[below] > 1.0)
    assert np.all(stable[above] == 1)


def test_nu2_dte_matches_time_integration_and_independent_hb(frc):
    _, body, summary = frc
    two = body[body[:, COLUMNS.index("nu")] == 2]
    row = two[-1]
    assert row[0] == pytest.approx(27000.0)
    p2p, rms = row[COLUMNS.index("dte_p2p_um")], row[COLUMNS.index("dte_rms_um")]

    model = build_model(load_config(EXAMPLE, ['boundary.output="torques"']))
    omega = rpm_to_rad_s(27000.0)
    ti = simulate(model, omega, max_cycles=1500, rtol=1e-8, steady_tolerance=1e-6)
    assert ti.period_cycles == 2
    assert p2p == pytest.approx(ti.summary["dte_p2p_um"], rel=0.01)
    assert rms == pytest.approx(ti.summary["dte_rms_um"], rel=0.01)

    # independent nu = 2 solve: from the embedded nu = 1 solution plus a half-order kick
    sol1 = solve_periodic(model, omega, harmonics=8, samples=256)
    z0 = embed_subharmonic(sol1.z, model.ndof, 8, 16)
    z0[half_order_indices(model.ndof, 16)[:2]] = 2.0
    hb2 = solve_period_doubled(model, omega, z0, harmonics=16, samples=512).summary()
    assert p2p == pytest.approx(hb2["dte_p2p_um"], rel=0.01)


def test_switch_off_and_cost_rule(tmp_path):
    _, body, summary = _run(tmp_path, "--no-period-doubling")
    assert np.all(body[:, COLUMNS.index("nu")] == 1)
    assert summary["period_doubling"] == [] and "off" in summary["period_doubling_rule"]

    cfg = load_config(EXAMPLE, [])  # spring boundary: ndof 2
    model = build_model(cfg)
    args = SimpleNamespace(period_doubling=None)
    h_max = (PD_AUTO_MAX_UNKNOWNS // model.ndof - 1) // 4
    assert period_doubling_enabled(cfg, args, model, h_max, 1)[:2] == (True, True)
    assert period_doubling_enabled(cfg, args, model, h_max + 1, 1)[:2] == (True, False)
    assert period_doubling_enabled(cfg, SimpleNamespace(period_doubling=True), model, 99, 1)[:2] == (True, True)
    assert period_doubling_enabled(cfg, args, model, 8, 2)[:2] == (False, False)
    linear = model.replace(contact="linear")
    assert period_doubling_enabled(cfg, args, linear, 8, 1)[:2] == (True, False)
    # NLTV friction without backlash: a non-linear model whose nu = 2 branch friction alone bounds
    nltv = build_model(load_config(EXAMPLE, ['friction.model="NLTV"', 'friction.law="arctan"', 'mesh.backlash_um=0']))
    assert not nltv.is_linear and nltv.mesh_is_linear
    locate, follow, why = period_doubling_enabled(cfg, args, nltv, 4, 1)
    assert (locate, follow) == (True, False) and "backlash" in why
    assert period_doubling_enabled(cfg, SimpleNamespace(period_doubling=True), nltv, 4, 1)[:2] == (True, True)
    assert not math.isnan(h_max)


def test_crossings_located_in_step_match_one_by_one_and_scipys_dop853(monkeypatch):
    """NLTV arctan, soft spring (the paper's pair), H = 32, N = 256: two -1 crossings (near 5270
    and 5380 rpm) need the variational monodromy. Located together, each step one batched
    evaluation for both, they are the crossings located one segment at a time (to the speed
    tolerance) for fewer evaluations; scipy's DOP853 along the same orbits (an integrator that
    shares no code with the compiled one) puts a multiplier on either side of -1 two tolerances
    either side of each."""
    from hbgear.engine import bifurcation
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.monodromy import monodromy_variational, state_synthesis
    from hbgear.engine.response import newton_solve
    from hbgear.gear.system import GearSystem

    model = build_model(load_config(Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml",
                                    ["friction.model='NLTV'", "friction.law='arctan'"]))
    system = GearSystem(model)
    harmonics, samples = 32, 256
    hb = HarmonicBalance(model.ndof, harmonics, 1, samples)
    p = rpm_to_rad_s(np.array([5255.0, 5285.0, 5370.0, 5395.0]))
    z = np.stack([solve_periodic(model, w, harmonics=harmonics, samples=samples).z for w in p])
    segments = [(p[0], z[0], p[1], z[1]), (p[2], z[2], p[3], z[3])]
    calls = []
    batched = bifurcation.exact_negative_multipliers
    monkeypatch.setattr(bifurcation, "exact_negative_multipliers", lambda *a, **k: calls.append(1) or batched(*a, **k))

    def solve(w, z0):
        return newton_solve(hb, system, w, z0, tolerance=1e-9, max_iterations=30).z

    def locate(parts):
        calls.clear()
        found = bifurcation.locate_period_doublings(system, hb, solve, parts)
        for point, why in found:
            assert point is not None, why
            assert point.multiplier == pytest.approx(-1.0, abs=1e-6)
        return [point.p for point, _ in found], len(calls)

    together, calls_together = locate(segments)
    alone = [locate([segment]) for segment in segments]
    assert together == pytest.approx([w for (w,), _ in alone], rel=2e-7)
    assert calls_together < sum(n for _, n in alone)
    for w, (pa, _, pb, _) in zip(together, segments):
        assert min(pa, pb) < w < max(pa, pb)
        sides = np.array([w * (1 - 2e-7), w * (1 + 2e-7)])
        zs = np.stack([hb.decode(system, solve(x, z[0] if x < p[1] else z[2]))[0] for x in sides])
        base = np.array([float(hb.base_frequency(system, x)) for x in sides])
        phi = monodromy_variational(system, sides, state_synthesis(zs, harmonics, base), 1, rtol=1e-11, atol=1e-13,
                                    integrator="DOP853")
        mu = [min((m.real for m in np.linalg.eigvals(f) if abs(m.imag) < 1e-9 and m.real < 0), default=np.nan)
              for f in phi]
        assert (mu[0] + 1.0) * (mu[1] + 1.0) < 0, (w, mu)


def test_a_segment_whose_multipliers_fail_is_reported_and_the_others_located(monkeypatch):
    """LTV (the multipliers do not depend on the solution: nothing is solved): the batch with a
    failing point is redone point by point; that segment says what failed, the other one is
    located (at the crossing the example's frc reports, 5268.05 rpm)."""
    from hbgear.engine import bifurcation
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.system import GearSystem

    model = build_model(load_config(Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"))
    system = GearSystem(model)
    hb = HarmonicBalance(model.ndof, 8, 1, 64)
    p = rpm_to_rad_s(np.array([5250.0, 5290.0, 5370.0, 5395.0]))
    zero = np.zeros(hb.size)
    exact = bifurcation.exact_negative_multipliers

    def failing_at_the_second_segment(system, hb, zs, ps):
        if any(abs(w - p[2]) < 1e-9 for w in ps):
            raise RuntimeError("no multiplier here (test)")
        return exact(system, hb, zs, ps)

    monkeypatch.setattr(bifurcation, "exact_negative_multipliers", failing_at_the_second_segment)

    (first, why_first), (second, why) = bifurcation.locate_period_doublings(
        system, hb, lambda w, z0: zero, [(p[0], zero, p[1], zero), (p[2], zero, p[3], zero)])
    assert first is not None, why_first
    assert first.p == pytest.approx(rpm_to_rad_s(5268.05), rel=2e-6)
    assert first.multiplier == pytest.approx(-1.0, abs=1e-6)
    assert second is None and why.startswith("locating the crossing failed: RuntimeError: no multiplier here")


def test_nu2_branch_on_the_soft_spring_counts_its_mean_in_the_springs_units(monkeypatch):
    """On the soft output spring with formulation B friction the spring's mean wind-up follows
    the response ``spring_stiffness_ratio`` (5e5) times more than the mesh; the ``nu = 2`` branch
    is continued in the curve's metric (:func:`hbgear.engine.metric.arclength_sizes`), so it does
    not crawl: the backlash pair (Coulomb 0.05, H = 8, N = 256), its crossing near 28,230 rpm,
    reached 27,000 rpm in 34 points against 438 in plain unknowns (the relieved ISO pair's two
    branches: 55 points against 2355, its command 57 s against 245 s). Only the metric changes:
    the sized branch's points lie on the plain one, and both end at the range end."""
    import hbgear.engine.bifurcation as bf
    from hbgear.gear.system import GearSystem

    model = build_model(load_config(EXAMPLE, ["friction.law='coulomb'", "friction.mu0=0.05",
                                              "friction.formulation='B'"]))
    system = GearSystem(model)
    assert not model.is_linear and system.arclength_mean_scales(1.0) is not None
    hb = bf.HarmonicBalance(system.ndof, 8, 1, 256)
    pa, pb = rpm_to_rad_s(28300.0), rpm_to_rad_s(28150.0)

    def solve(p, z0=None):
        return np.asarray(solve_periodic(model, float(p), harmonics=8, samples=256, z0=z0).z)

    (point, why), = bf.locate_period_doublings(system, hb, solve, [(pa, solve(pa), pb, solve(pb))])
    assert point is not None, why
    assert abs(point.p - rpm_to_rad_s(28231.1)) < 1e-4 * point.p
    lo, hi = rpm_to_rad_s(27000.0), rpm_to_rad_s(29000.0)

    def follow():
        return bf.follow_period_doubled(system, point, 8, lo, hi, harmonics2=16, samples2=512, max_points=1000)

    sized = follow()
    monkeypatch.setattr(bf, "arclength_sizes", lambda *args: None)  # the plain unknowns
    plain = follow()
    assert sized.status == plain.status == "reached range end"
    assert sized.p[-1] == pytest.approx(lo, rel=1e-12) and plain.p[-1] == pytest.approx(lo, rel=1e-12)
    assert len(sized.p) < len(plain.p) / 5, (len(sized.p), len(plain.p))
    # every sized point on the plain branch: within one plain step of the nearest plain solution
    # (the plain points are dense; the branch turns in speed near the crossing), the ends equal
    span = np.max(np.abs(plain.z))
    assert np.max(np.abs(sized.z[-1] - plain.z[-1])) <= 1e-7 * span
    steps = np.max(np.abs(np.diff(plain.z, axis=0)), axis=1)
    for z in sized.z[1:-1]:
        gaps = np.max(np.abs(plain.z - z), axis=1)
        k = int(np.argmin(gaps))
        assert gaps[k] <= steps[max(k - 1, 0):k + 1].max(), (k, gaps[k])
