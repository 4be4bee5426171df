"""Paper Fig. 14 in kind: ratio of LTV to NLTV peak-to-peak DTE over speed x contact ratio.

    python validation/fig14_ltv_nltv_ratio.py

Writes validation/out/fig14_ltv_nltv_ratio.png and validation/out/fig14_ltv_nltv_ratio.md.
Reference pair (``examples/paper_table1.toml``: soft output spring, Coulomb mu0 = 0.1,
formulation A, zeta = 0.001 as in the paper's Fig. 12 by default; ``--zeta 0.01`` for the
previous run), k_max and k_min held as Gamma varies. Both models by harmonic
balance (nu = 1) on a coarse grid, the NLTV solution continued along speed; where the LTV
model is unstable (exact monodromy) its steady response does not exist and the ratio is
marked infinite, as the paper's gamma > 100 contours do.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from hbgear import stability as st
from hbgear.config import load_config
from hbgear.errors import ConvergenceError
from hbgear.solve import rpm_to_rad_s, solve_periodic

HERE = Path(__file__).resolve().parent
OUT = HERE / "out"
EXAMPLE = HERE.parent / "examples" / "paper_table1.toml"


def ratio_map(speeds_rpm, ratios, *, harmonics: int = 32, samples: int = 256, zeta: float = 0.01):
    """``(ratio, p2p_ltv, p2p_nltv, max|mult| LTV)``, each ``(len(ratios), len(speeds))``.

    ``ratio = inf`` where the LTV model is unstable, ``nan`` where NLTV HB did not converge.
    """
    base = [f"mesh.damping_ratio={zeta}", "friction.mu0=0.1", 'friction.law="coulomb"', 'boundary.output="spring"']
    cfg_ltv = load_config(EXAMPLE, base + ['friction.model="LTV"'])
    cfg_nltv = load_config(EXAMPLE, base + ['friction.model="NLTV"'])
    shape = (len(ratios), len(speeds_rpm))
    p_ltv, p_nl, mult = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    for i, gamma in enumerate(ratios):
        ltv = st.model_at_contact_ratio(cfg_ltv, gamma)
        nltv = st.model_at_contact_ratio(cfg_nltv, gamma)
        omegas = rpm_to_rad_s(np.asarray(speeds_rpm, float))
        mult[i] = np.max(np.abs(st.multipliers_linear(ltv, omegas)), axis=-1)
        z = None
        for j, omega in enumerate(omegas):
            p_ltv[i, j] = solve_periodic(ltv, float(omega), harmonics=harmonics, samples=samples).summary()["dte_p2p_um"]
            try:
                sol = solve_periodic(nltv, float(omega), harmonics=harmonics, samples=samples, z0=z)
            except ConvergenceError:
                z = None
                continue
            z = sol.z
            p_nl[i, j] = sol.summary()["dte_p2p_um"]
    ratio = p_ltv / p_nl
    ratio = np.where(mult > 1.0 + 1e-9, np.inf, ratio)
    return ratio, p_ltv, p_nl, mult


def main(speeds=np.arange(6000.0, 32001.0, 500.0), ratios=np.array([1.35, 1.45, 1.55, 1.65]), zeta: float = 0.001):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(exist_ok=True)
    t0 = time.perf_counter()
    ratio, p_ltv, p_nl, mult = ratio_map(speeds, ratios, zeta=zeta)
    elapsed = time.perf_counter() - t0

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    shown = np.where(np.isinf(ratio), np.nan, ratio)
    mesh = axes[0].pcolormesh(speeds, ratios, shown, shading="nearest", cmap="viridis")
    fig.colorbar(mesh, ax=axes[0], label="p2p LTV / p2p NLTV")
    ii, jj = np.nonzero(np.isinf(ratio))
    axes[0].plot(speeds[jj], ratios[ii], "x", color="tab:red", label="LTV unstable (ratio infinite)")
    axes[0].contour(speeds, ratios, mult, levels=[1.0], colors="tab:red", linewidths=1)
    axes[0].set_xlabel("pinion speed [rpm]")
    axes[0].set_ylabel("contact ratio")
    axes[0].legend(fontsize=8, loc="upper left")
    axes[0].set_title("Fig. 14 in kind: LTV / NLTV peak-to-peak DTE", fontsize=10)
    for i, g in enumerate(ratios):
        axes[1].semilogy(speeds, shown[i], "o-", ms=3, label=f"Gamma {g:.2f}")
    axes[1].set_xlabel("pinion speed [rpm]")
    axes[1].set_ylabel("ratio (finite values)")
    axes[1].grid(alpha=0.3, which="both")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "fig14_ltv_nltv_ratio.png", dpi=120)

    finite = np.isfinite(ratio)
    k = np.unravel_index(np.nanargmax(np.where(finite, ratio, np.nan)), ratio.shape)
    rows = "\n".join(
        f"| {g:.2f} | {np.sum(np.isinf(ratio[i]))} | "
        f"{np.nanmin(np.where(np.isfinite(ratio[i]), ratio[i], np.nan)):.3f} - "
        f"{np.nanmax(np.where(np.isfinite(ratio[i]), ratio[i], np.nan)):.3f} | "
        f"{speeds[np.nanargmax(np.where(np.isfinite(ratio[i]), ratio[i], np.nan))]:.0f} |"
        for i, g in enumerate(ratios)
    )
    unstable = ", ".join(f"{speeds[j]:.0f}@{ratios[i]:.2f}" for i, j in zip(ii, jj))
    # finite ratios next to an LTV-unstable grid point (same Gamma, neighbouring speed) vs the rest
    near = np.zeros(ratio.shape, bool)
    for i, j in zip(ii, jj):
        for jn in (j - 1, j + 1):
            if 0 <= jn < len(speeds) and np.isfinite(ratio[i, jn]):
                near[i, jn] = True
    far = finite & ~near
    near_txt = (f"{np.min(ratio[near]):.3f} - {np.max(ratio[near]):.3f} ({int(near.sum())} points)"
                if near.any() else "none (no finite point next to an unstable one)")
    far_txt = f"{np.min(ratio[far]):.3f} - {np.max(ratio[far]):.3f} ({int(far.sum())} points)" if far.any() else "none"
    n_big = int(np.sum(finite & (ratio > 100.0)))
    dev = np.abs(np.where(finite, ratio, np.nan) - 1.0)
    text = f"""# Fig. 14 in kind: LTV / NLTV peak-to-peak DTE

Script `validation/fig14_ltv_nltv_ratio.py`; figure `fig14_ltv_nltv_ratio.png`.
Grid {len(speeds)} speeds ({speeds[0]:.0f}-{speeds[-1]:.0f} rpm, step {speeds[1] - speeds[0]:.0f}) x
{len(ratios)} contact ratios; zeta = {zeta:g}, Coulomb mu0 = 0.1 (NLTV regularised,
v_reg = 5 mm/s), formulation A, soft spring; both models by HB, nu = 1, H = 32, N = 256;
{elapsed:.0f} s in all.

| Gamma | LTV-unstable grid points | finite ratio range | speed of the largest finite ratio [rpm] |
|---|---|---|---|
{rows}

What the numbers show:
- Finite ratios (LTV stable): {np.nanmin(np.where(finite, ratio, np.nan)):.3f} - {ratio[k]:.3f}; largest at
  {speeds[k[1]]:.0f} rpm, Gamma {ratios[k[0]]:.2f} (p2p LTV {p_ltv[k]:.3f} um, NLTV {p_nl[k]:.3f} um);
  {int(np.sum(dev <= 0.05))} of {int(finite.sum())} finite points lie within 5 % of 1.
- Next to an LTV-unstable grid point: {near_txt}; elsewhere: {far_txt}.
- Finite ratios above the paper's threshold 100: {n_big}.
- LTV-unstable grid points (exact monodromy; ratio set to infinity, not computed):
  {unstable or 'none'}.
- NLTV HB did not converge at {int(np.sum(np.isnan(p_nl)))} point(s) (left blank).

## Agreement with the paper

- Agrees: where both models are stable and away from the zones the ratio is close to 1
  (friction acts mainly as an excitation; the paper's "nearly identical" responses), and
  the LTV-unstable points lie at w_m ~ 2 w_n and at its sub-/super-harmonic zones, moving
  with Gamma as in Fig. 13.
- Differs: the paper's contours reach gamma > 100 around the unstable zones, and its inner
  contours mark NLTV-stabilised zones. A comparison of periodic HB solutions cannot show
  that: (i) where the LTV model is unstable its periodic solution exists (HB finds it) but
  is never reached, and the paper's gamma > 100 there is the ratio of an LTV *transient*
  growing for the simulated time to a bounded NLTV response, i.e. a number set by the
  integration length and the threshold, not a property of two steady states; (ii) just
  outside the zones both periodic solutions are resonant through the same k(t) mechanism
  and the NLTV friction changes their amplitude only by the small effective damping it adds
  (see the numbers above), so the ratio of steady p2p stays O(1); the paper's large ratios
  near the zone edges are also consistent with slowly decaying LTV transients at
  zeta = 0.001 (multipliers just below 1) not having settled within the integration time.
  (iii) The NLTV solutions are not checked for stability here; fig12_ltv_vs_nltv.md shows
  that at the zone near 1490 rpm the NLTV nu = 1 solution is itself unstable over most of
  the zone (formulation A: everywhere it was tested), so NLTV "stabilisation" is not
  generic in this model. The grid (step {speeds[1] - speeds[0]:.0f} rpm) resolves only the wide
  zones; the narrow high-order zones fall between grid speeds.
"""
    (OUT / "fig14_ltv_nltv_ratio.md").write_text(text)
    print(text)
    return ratio


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--zeta", type=float, default=0.001, help="mesh damping ratio (default 0.001)")
    main(zeta=parser.parse_args().zeta)
