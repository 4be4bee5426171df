"""Paper Fig. 12 in kind: in an unstable zone of the LTV model the LTV response grows without
bound while the NLTV response (friction from the instantaneous sliding velocity) stays bounded.

    /tmp/venv/bin/python validation/fig12_ltv_vs_nltv.py

Writes validation/out/fig12_ltv_vs_nltv.png and validation/out/fig12_ltv_vs_nltv.md.
Paper conditions: zeta = 0.001, mu0 = 0.1 (Coulomb), Gamma = 1.473, formulation A, soft output
spring. The paper's "1490 rpm" is read as w_m = 2 w_n / 18 (= 1489 rpm for our pair): the zone
used is the unstable zone of OUR pair found there by the exact LTV monodromy (below).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from hbgear import stability as st
from hbgear.build import build_model
from hbgear.config import load_config
from hbgear.solve import rad_s_to_rpm, rpm_to_rad_s, solve_periodic
from hbgear.simulate import simulate

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"
EXAMPLE = HERE.parent / "examples" / "paper_table1.toml"
SETTINGS = ["mesh.damping_ratio=0.001", "gear.contact_ratio=1.473", "friction.mu0=0.1", 'friction.law="coulomb"',
            'boundary.output="spring"', 'friction.formulation="A"']


def models():
    ltv = build_model(load_config(EXAMPLE, SETTINGS + ['friction.model="LTV"']))
    nltv = build_model(load_config(EXAMPLE, SETTINGS + ['friction.model="NLTV"']))
    return ltv, nltv


def unstable_zones(model, rpm_lo=1300.0, rpm_hi=1700.0, steps=8001):
    """``[(start_rpm, stop_rpm, max_multiplier_modulus, sign of the leading multiplier)]`` of the LTV model."""
    speeds = np.linspace(rpm_lo, rpm_hi, steps)
    mult = st.multipliers_linear(model, rpm_to_rad_s(speeds))
    mod = np.max(np.abs(mult), axis=-1)
    bad = mod > 1.0 + 1e-9
    zones = []
    i = 0
    while i < steps:
        if bad[i]:
            j = i
            while j + 1 < steps and bad[j + 1]:
                j += 1
            k = i + int(np.argmax(mod[i : j + 1]))
            lead = mult[k][np.argmax(np.abs(mult[k]))]
            zones.append((float(speeds[i]), float(speeds[j]), float(mod[k]), float(np.sign(lead.real)), float(speeds[k])))
            i = j + 1
        else:
            i += 1
    return zones


def march(model, omega, cycles):
    """DTE over `cycles` mesh periods from the quasi-static state (numpy, piecewise between breakpoints).

    The same start as :func:`hbgear.simulate.simulate`, with no steady-state test, so a growing
    response can be shown. Returns ``(t_cycles, delta_um)``.
    """
    if model.coupling == "NLTV" and model.friction.discontinuous:
        model = model.replace(friction=model.friction.regularized(5e-3))
    _, _, wm = model.speeds(omega)
    tm = 2 * math.pi / wm
    n = model.ndof
    minv = np.linalg.inv(np.asarray(model.mass_matrix(), float))
    _, u_static = model.static_state(omega)
    u_static = float(u_static)
    edges = np.concatenate([np.asarray(model.phase_breakpoints(), float), [1.0]])
    s0 = 1e-12
    y = np.zeros(2 * n)
    y[0] = model.normal_load_N / float(model.mesh_stiffness(np.asarray(s0)))
    ts, ds = [], []
    for c in range(cycles):
        for a, b in zip(edges[:-1], edges[1:]):
            lo, hi = a + 1e-12, b - 1e-12

            def f(t, yy, a=a, lo=lo, hi=hi):
                s = min(max(a + t / tm, lo), hi)
                force = model.generalized_force(np.float64(s), yy[:n], yy[n:], omega, "all", u_static, 0.0)
                return np.concatenate([yy[n:], minv @ np.asarray(force, float)])

            t_eval = np.linspace(0.0, (b - a) * tm, max(4, int(64 * (b - a))))
            sol = solve_ivp(f, (0.0, (b - a) * tm), y, method="DOP853", rtol=1e-9, atol=1e-15, t_eval=t_eval)
            ts.append(c + a + sol.t / tm)
            ds.append(sol.y[0])
            y = sol.y[:, -1]
            if not np.all(np.isfinite(y)) or abs(y[0]) > 1.0:
                break
    return np.concatenate(ts), 1e6 * np.concatenate(ds)


def main(cycles: int = 80, harmonics: int = 96):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    ltv, nltv = models()
    zones = unstable_zones(ltv)
    wn = math.sqrt(float(ltv.k_mean_N_per_m) / float(ltv.mass_equivalent_kg))
    nominal = rad_s_to_rpm(2 * wn / 18 / float(ltv.teeth_pinion))
    zone = min(zones, key=lambda z: abs(z[4] - 1490.0))
    rpm = zone[4]
    omega = rpm_to_rad_s(rpm)
    t_map = time.perf_counter() - t0

    t1 = time.perf_counter()
    t_ltv, d_ltv = march(ltv, omega, cycles)
    t_nl, d_nl = march(nltv, omega, cycles)
    t_march = time.perf_counter() - t1

    t2 = time.perf_counter()
    ti = simulate(nltv, omega, max_cycles=1500, rtol=1e-9, steady_tolerance=1e-6)
    t_ti = time.perf_counter() - t2
    t3 = time.perf_counter()
    nu = ti.period_cycles
    hb = solve_periodic(nltv, omega, harmonics=harmonics * nu, nu=nu, samples=8 * harmonics * nu)
    hb_sum = hb.summary()
    t_hb = time.perf_counter() - t3
    mult_nltv = st.floquet_multipliers(nltv, omega, solution=hb, method="variational")

    def growth(t, d):
        per = [np.ptp(d[(t >= c) & (t < c + 1)]) for c in range(int(t[-1]))]
        return np.asarray(per)

    g_ltv, g_nl = growth(t_ltv, d_ltv), growth(t_nl, d_nl)

    fig, axes = plt.subplots(3, 1, figsize=(8, 9))
    axes[0].plot(t_ltv, d_ltv, lw=0.6, color="tab:red")
    axes[0].set_title(f"(a) LTV, {rpm:.1f} rpm: grows without bound", fontsize=10)
    axes[1].plot(t_nl, d_nl, lw=0.6, color="tab:blue")
    axes[1].set_title("(b) NLTV, same conditions: bounded", fontsize=10)
    f = np.linspace(0, 1, 2001)
    q, _ = hb.state_at(f)
    axes[2].plot(ti.s[: len(ti.s) // 2] if nu == 1 else np.arange(ti.q.shape[1]) / (ti.q.shape[1] / 2),
                 1e6 * ti.q[0][: len(ti.s) // 2] if nu == 1 else 1e6 * ti.q[0], ".", ms=2, color="0.5", label="TI steady")
    axes[2].plot(f * nu, 1e6 * q[0], color="k", lw=1, label=f"HB nu={nu}, H={hb.harmonics}")
    axes[2].set_title("(c) NLTV steady state: HB against time integration", fontsize=10)
    axes[2].legend(fontsize=8)
    for ax in axes[:2]:
        ax.set_xlabel("mesh cycles")
    axes[2].set_xlabel("mesh cycles")
    for ax in axes:
        ax.set_ylabel("DTE [um]")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(OUT / "fig12_ltv_vs_nltv.png", dpi=120)

    rel_p2p = hb_sum["dte_p2p_um"] / ti.summary["dte_p2p_um"] - 1
    rel_rms = hb_sum["dte_rms_um"] / ti.summary["dte_rms_um"] - 1
    zone_rows = "\n".join(
        f"| {a:.2f} - {b:.2f} | {m:.4f} | {'+1 (saddle-node type)' if s > 0 else '-1 (period doubling)'} |"
        for a, b, m, s, _ in zones
    )
    text = f"""# Fig. 12 in kind: LTV diverges, NLTV stays bounded

Script `validation/fig12_ltv_vs_nltv.py`; figure `fig12_ltv_vs_nltv.png`.
Paper conditions: zeta = 0.001, mu0 = 0.1 (Coulomb; NLTV regularised with v_reg = 5 mm/s),
Gamma = 1.473, formulation A, soft output spring; start from the static state (delta' = 0).

## Which zone

The paper ran 1490 rpm. For our pair w_n = {wn:.0f} rad/s, and w_m = 2 w_n / 18 is
{nominal:.1f} rpm: the paper's speed sits at the 18th-order parametric zone (an even order,
so the leading multiplier leaves through +1, what the paper calls a saddle-node instability).
Exact LTV monodromy, 1300-1700 rpm (step 0.05 rpm), unstable zones of our pair:

| zone [rpm] | max abs multiplier per mesh period | leaves through |
|---|---|---|
{zone_rows}

Used: **{rpm:.2f} rpm**, the most unstable speed of the zone {zone[0]:.2f}-{zone[1]:.2f} rpm
(multiplier {zone[2]:.4f} per mesh period).

## Results

- LTV, {cycles} mesh cycles from the static state: peak-to-peak DTE per cycle grows from
  {g_ltv[1]:.3g} um (cycle 1) to {g_ltv[-1]:.3g} um (cycle {len(g_ltv)}), factor
  {g_ltv[-1] / g_ltv[len(g_ltv) // 2]:.3g} over the last {len(g_ltv) - len(g_ltv) // 2} cycles
  (the multiplier predicts {zone[2] ** (len(g_ltv) - len(g_ltv) // 2):.3g}).
- NLTV, same start: peak-to-peak per cycle {g_nl[1]:.3g} um (cycle 1), {g_nl[-1]:.3g} um
  (cycle {len(g_nl)}): bounded.
- NLTV steady state by time integration: period {nu} mesh cycle(s) after {ti.cycles} cycles,
  DTE p2p {ti.summary['dte_p2p_um']:.4f} um, RMS {ti.summary['dte_rms_um']:.4f} um.
- NLTV by harmonic balance (nu = {nu}, H = {hb.harmonics}, N = {hb.samples}): p2p
  {hb_sum['dte_p2p_um']:.4f} um, RMS {hb_sum['dte_rms_um']:.4f} um; differences
  {100 * rel_p2p:+.2f} % (p2p), {100 * rel_rms:+.2f} % (RMS).
- Floquet multipliers of the NLTV HB solution (variational equations): max modulus
  {np.max(np.abs(mult_nltv)):.5f} (stable: {st.is_stable(mult_nltv)}).

Timings: zone search {t_map:.1f} s, transients {t_march:.1f} s, NLTV TI {t_ti:.1f} s, HB {t_hb:.1f} s.

## Agreement with the paper

- Agrees: the LTV model is unstable in the zone near the paper's speed and its response grows
  without bound from the static state; the NLTV model under the same conditions settles to a
  bounded periodic response (the instantaneous sliding velocity makes friction depend on the
  vibration, and it limits the growth).
- Differs in detail: our zone lies at {zone[0]:.0f}-{zone[1]:.0f} rpm rather than at 1490 rpm
  (the paper's missing parameters were completed differently; see MODEL.md section 1), and the
  bounded NLTV response here is period-1, consistent with a +1 multiplier.
"""
    (OUT / "fig12_ltv_vs_nltv.md").write_text(text)
    print(text)
    return dict(rpm=rpm, zone=zone, ti=ti.summary, hb=hb_sum, rel_p2p=rel_p2p, rel_rms=rel_rms)


if __name__ == "__main__":
    main()
