"""Paper Fig. 13 in kind: the primary parametric instability zone over speed x contact ratio,
without friction and with Coulomb friction (formulations A and B), unit contours overlaid.

    python validation/fig13_stability_map.py

Writes validation/out/fig13_stability_map.png and validation/out/fig13_stability_map.md.
LTV model, boundary "torques" (the DTE alone, the paper's single-DOF stability model),
k_max and k_min held as Gamma varies (k_mean follows), zeta from the example config (0.01).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

import hbgear
from hbgear.build import model_at_contact_ratio
from hbgear.config import load_config

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"
EXAMPLE = HERE.parent / "examples" / "paper_table1.toml"


def zone_edges(speeds, values):
    """Lower/upper speed where max|mult| crosses 1 (linear interpolation), nan if none."""
    above = values > 1.0
    if not above.any():
        return math.nan, math.nan
    i, j = np.flatnonzero(above)[[0, -1]]

    def cross(a, b):
        return speeds[a] + (1.0 - values[a]) * (speeds[b] - speeds[a]) / (values[b] - values[a])

    lo = cross(i - 1, i) if i > 0 else math.nan
    hi = cross(j, j + 1) if j + 1 < len(speeds) else math.nan
    return lo, hi


def main():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    speeds = np.linspace(20000.0, 32000.0, 241)
    ratios = np.linspace(1.35, 1.65, 61)
    cases = {
        "A, mu0 = 0": ('friction.formulation="A"', "friction.mu0=0.0"),
        "A, mu0 = 0.1": ('friction.formulation="A"', "friction.mu0=0.1"),
        "B, mu0 = 0.1": ('friction.formulation="B"', "friction.mu0=0.1"),
    }
    maps, timings = {}, {}
    for name, extra in cases.items():
        cfg = load_config(EXAMPLE, ['boundary.output="torques"', 'friction.model="LTV"', *extra])
        t0 = time.perf_counter()
        maps[name] = hbgear.stability_map(cfg, speeds, ratios)
        timings[name] = time.perf_counter() - t0
    cfg0 = load_config(EXAMPLE, ['boundary.output="torques"'])
    m0 = model_at_contact_ratio(cfg0, 1.433)
    wn = math.sqrt(m0.k_mean_N_per_m / m0.mass_equivalent_kg)
    primary_rpm = 2 * wn / m0.teeth_pinion * 60 / (2 * np.pi)

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6), layout="constrained", sharey=True)
    from hbgear.outputs.plots import stability_map_figure as plot_stability_map

    for ax, name in zip(axes[:2], ["A, mu0 = 0", "B, mu0 = 0.1"]):
        plot_stability_map(speeds, ratios, maps[name], title=f"LTV {name}: max |multiplier|", ax=ax)
    ax = axes[2]
    styles = {"A, mu0 = 0": ("k", "-"), "A, mu0 = 0.1": ("tab:green", ":"), "B, mu0 = 0.1": ("tab:red", "--")}
    for name, (colour, ls) in styles.items():
        ax.contour(speeds, ratios, maps[name], levels=[1.0], colors=colour, linestyles=ls, linewidths=1.4)
        ax.plot([], [], color=colour, ls=ls, label=name)
    ax.set_xlim(23000, 31000)
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_title("unit contours (inside: unstable)", fontsize=8)
    ax.legend(fontsize=8)
    fig.suptitle("Fig. 13 in kind: primary parametric instability zone (w_m ~ 2 w_n), with and without friction")
    fig.savefig(OUT / "fig13_stability_map.png", dpi=130)

    # numbers for the note
    rows = []
    for g_target in (1.35, 1.433, 1.5, 1.65):
        k = int(np.argmin(abs(ratios - g_target)))
        ea = zone_edges(speeds, maps["A, mu0 = 0"][k])
        eb = zone_edges(speeds, maps["B, mu0 = 0.1"][k])
        rows.append((ratios[k], ea, eb, maps["A, mu0 = 0"][k].max(), maps["B, mu0 = 0.1"][k].max()))
    same_a = float(np.max(np.abs(maps["A, mu0 = 0"] - maps["A, mu0 = 0.1"])))
    area = {n: float(np.mean(v > 1.0)) for n, v in maps.items()}
    lines = [
        "# Fig. 13 in kind: instability zone with and without friction",
        "",
        "Script: `validation/fig13_stability_map.py`; figure `fig13_stability_map.png`.",
        f"Grid {len(speeds)} speeds (20,000-32,000 rpm) x {len(ratios)} contact ratios (1.35-1.65); LTV,",
        "boundary `torques` (DTE only), zeta = 0.01, Coulomb friction, k_max = 720 MN/m and",
        "k_min = 451.9 MN/m held (k_mean follows Gamma). Multipliers per mesh period from the exact",
        "product of matrix exponentials (formulation A) and 16 fourth-order Magnus steps per segment",
        "(formulation B, where xi_j(t) makes the friction coefficients linear in t).",
        "",
        f"Primary zone expected at w_m = 2 w_n: w_n = sqrt(k_mean/m_e) = {wn:.0f} rad/s at Gamma = 1.433,",
        f"Omega_p = 2 w_n / Zp = {primary_rpm:.0f} rpm.",
        "",
        "| Gamma | zone A, mu0=0 [rpm] | zone B, mu0=0.1 [rpm] | shift of lower / upper edge [rpm] | max mult A | max mult B |",
        "|---|---|---|---|---|---|",
    ]
    for g, ea, eb, ma, mb in rows:
        lines.append(
            f"| {g:.3f} | {ea[0]:.0f} - {ea[1]:.0f} | {eb[0]:.0f} - {eb[1]:.0f} | "
            f"{eb[0] - ea[0]:+.0f} / {eb[1] - ea[1]:+.0f} | {ma:.4f} | {mb:.4f} |"
        )
    lines += [
        "",
        f"Unstable fraction of the grid: A mu0=0 {area['A, mu0 = 0']:.4f}, A mu0=0.1 {area['A, mu0 = 0.1']:.4f}, "
        f"B mu0=0.1 {area['B, mu0 = 0.1']:.4f}.",
        f"Formulation A with and without friction: max difference of max|mult| = {same_a:.1e}. This holds by",
        "construction (friction is a pure excitation in A, absent from the homogeneous equations whose",
        "monodromy is mapped), so it is a check of the code, not evidence for the paper's statement.",
        "",
        "Timings (whole map, one core): " + ", ".join(f"{n}: {t:.2f} s" for n, t in timings.items()) + ".",
        "",
        "## What matches the paper",
        "",
        "- One closed instability zone around w_m = 2 w_n (a real multiplier through -1: period",
        "  doubling), widest near Gamma = 1.45-1.5 where the first harmonic of the rectangular k(t),",
        "  proportional to sin(pi (Gamma - 1)), is largest, and moving to higher speed as Gamma grows",
        "  (k_mean grows with k_max, k_min held).",
        "- Friction in formulation A has no effect on stability: identical maps, by construction (in A",
        "  friction is an excitation, which the paper also says). In formulation B (friction as a",
        "  time-varying parameter) the zone moves to the",
        "  right: its upper edge by about +57 rpm at every contact ratio, its lower edge by -15 to",
        "  +11 rpm, i.e. the centre moves right by 20-35 rpm (0.1 %) and the zone widens by ~0.5-2 %;",
        "  max |multiplier| grows by ~0.004. 'Inclusion of friction only has the effect of shifting",
        "  this region to the right, but the overall influence is negligible' -- the same in kind.",
        "",
        "## What does not match (or cannot be checked)",
        "",
        "- The paper's shift looks like a rigid translation of the whole zone; here mainly the upper",
        "  (high-speed) edge moves, the lower edge barely (and moves left at low Gamma), so part of",
        "  the effect is a widening. The paper's axes cannot be read precisely from the text",
        "  extraction, so the size of its shift cannot be compared; its damping ratio for Fig. 13 is",
        "  not stated (we use 0.01, which sets the width of the zone).",
        "- The paper's Fig. 13 is drawn near 'one unstable zone' without stating which; with the",
        "  completed Table 1 values the primary zone sits at about 26,800 rpm (twice the primary",
        "  resonance speed 13,400 rpm). With zeta = 0.01 the j = 2 zone (w_m = w_n, 13,400 rpm) is",
        "  closed (it needs zeta <~ 0.003), the j = 3 zone (8,930 rpm) is open.",
        "- Only the single-DOF `torques` model is mapped here; with the `spring` boundary the soft",
        "  output mode adds a multiplier of modulus 1 to within ~1e-10 everywhere (the zone is the",
        "  same; the map command draws its unit contour at 1 + 1e-6 for that reason).",
    ]
    (OUT / "fig13_stability_map.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
