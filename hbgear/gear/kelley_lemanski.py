r"""Benedict–Kelley / Kelley–Lemanski empirical friction coefficient for lubricated gear teeth.

**The law in its original (US customary) units** (Benedict & Kelley 1961):

$$
|\mu| = 0.0127\, C_R \log_{10}\!\left(\frac{3.17\times10^{8}\, W}{\eta_0\, V_s\, V_e^{2}}\right),
\qquad C_R = \frac{50}{50 - S},
$$

- `W`: normal load per unit face width [lb/in];
- `eta0`: absolute (dynamic) viscosity of the oil at the inlet temperature [cP];
- `V_s`: sliding speed `|V1 - V2|` [in/s];
- `V_e`: "sum" (entraining) velocity `V1 + V2` -- the *sum* of the two surface rolling
  velocities, not their mean [in/s];
- `S`: average RMS roughness of the two surfaces, `(Rq1 + Rq2)/2` [micro-inch];
- `log10` is the decimal logarithm.

**What is, and is not, taken from Vaishya & Singh (2003), Eq. 2.** Their Eq. 2 (after Kelley &
Lemanski 1967) is $\mu = C_1 \frac{1}{1 - C_2 R_q}\log_{10}\big(C_3 w/(\eta_0 V_s V_r^2
(\rho_p+\rho_g)^2)\big)$, with empirical $C_1, C_2, C_3$ whose values it does not give. Taken
from it: the form in $R_q$, $w$ (load per unit length of contact), $\eta_0$, $V_s$ and $V_r$.
Not taken: the curvature factor $(\rho_p+\rho_g)^2$ (we could not check it against Kelley &
Lemanski's paper; it is left out, as in Benedict & Kelley's form) and the constants, which are
Benedict & Kelley's: $C_1 = 0.0127$, $C_2 = 1/(50\,\mu\text{in}) = 0.02\,\mu\text{in}^{-1}$
(so $1/(1 - C_2 R_q) \equiv C_R$) and $C_3 = 3.17\times10^{8}$ in the units above; this module
implements the Benedict–Kelley form that `MODEL.md` §3 names as the basis. The cap, the floor
and the sign (below) are ours.

**SI form, as implemented.** The inputs are SI. They are converted to the original units with
the named constants below, so the code stays close to the published formula. The equivalent
SI constant is

$$
|\mu| = 0.0127\, C_R \log_{10}\!\left(\frac{C_{3,SI}\, w}{\eta_0 V_s V_e^{2}}\right),\quad
C_{3,SI} = 3.17\times10^{8}\,\frac{\mathrm{LBF\_PER\_N}/\mathrm{INCH\_PER\_M}}
{\mathrm{CENTIPOISE\_PER\_PA\_S}\cdot\mathrm{INCH\_PER\_M}^{3}} \approx 2.9662\times10^{-2},
$$

with `w` in N/m, `eta0` in Pa s, and velocities in m/s (`KELLEY_C3_SI`). If the velocities were
taken in ft/s instead of in/s, the SI constant would be about 51.25 and `mu` would rise by
`0.0127 C_R log10(1728)` ≈ 0.041 `C_R`. See `docs/kelley_lemanski.md` for the evidence on the
units.

**Cap and floor.** Near the pitch point `V_s -> 0` the logarithm diverges, so the magnitude is
clipped to `[0, mu_cap]`. The default `mu_cap = 0.15` is the usual boundary-lubricated
steel-on-steel friction level (about 0.1–0.16). The lower clip at 0 covers the full-film regime,
where the argument drops below 1 and the formula would turn negative. To keep everything finite
and differentiable, `V_s`, `V_e`, `w` and `eta0` are floored at `TINY` before the logarithm (a
zero or negative load therefore gives `mu = 0`). The roughness is clipped to
`[0, ROUGHNESS_CLIP_UIN]` (45 µin, `C_R <= 10`) because `C_R` blows up at `S = 50` µin
(1.27 µm, `ROUGHNESS_LIMIT_UM`). Reject such inputs at config time; the clip only keeps
traced code finite.

**Sign convention.** This module returns the unsigned magnitude. The caller carries the
direction: `mu_j = sgn(Vs_j) * kelley_lemanski_magnitude(|Vs_j|, Vr_j, ...)` (`MODEL.md` §3:
`Vs < 0` in approach, `> 0` in recess). At `Vs = 0` exactly, `sgn` gives 0, although the
magnitude there is `mu_cap`.

**Validity.** The law is empirical. It was fitted to roller (disc) tests on a gear-simulating
machine, with mineral oils in mixed/boundary lubrication. We could not recover the tested
parameter ranges from the sources we had, so treat values far from gear-typical conditions
(`w` ~ 1e4–1e6 N/m, `V_s` ~ 0.1–20 m/s, `V_e` ~ 1–50 m/s) as extrapolation. The load is
taken per unit face width of one tooth pair's contact line.

References: A. Benedict & B. W. Kelley, "Instantaneous coefficients of gear tooth friction",
ASLE Trans. 4 (1961) 59–70. B. W. Kelley & A. J. Lemanski, "Lubrication of involute gearing",
Proc. IMechE 182(3A) (1967). S. Vaishya & R. Singh, "Strategies for modeling friction in gear
dynamics", ASME J. Mech. Des. 125 (2003) 383–393.
"""

from __future__ import annotations

import numpy

__all__ = [
    "LBF_PER_N",
    "INCH_PER_M",
    "CENTIPOISE_PER_PA_S",
    "MICROINCH_PER_UM",
    "KELLEY_C1",
    "KELLEY_C3_US",
    "KELLEY_C3_SI",
    "ROUGHNESS_LIMIT_UIN",
    "ROUGHNESS_LIMIT_UM",
    "ROUGHNESS_CLIP_UIN",
    "MU_CAP_DEFAULT",
    "TINY",
    "roughness_factor",
    "kelley_lemanski_magnitude",
]

# --- unit conversions (exact definitions: 1 in = 0.0254 m, 1 lbf = 4.4482216152605 N) ---
LBF_PER_N = 1.0 / 4.4482216152605
INCH_PER_M = 1.0 / 0.0254
CENTIPOISE_PER_PA_S = 1000.0
MICROINCH_PER_UM = 1e-6 / (0.0254 * 1e-6)  # 1 µm = 1e-6 m = 39.37 µin

# --- Benedict & Kelley (1961) constants, original units (lb/in, cP, in/s, µin) ---
KELLEY_C1 = 0.0127
KELLEY_C3_US = 3.17e8
ROUGHNESS_LIMIT_UIN = 50.0  # C_R = 50 / (50 - S) diverges here
ROUGHNESS_LIMIT_UM = ROUGHNESS_LIMIT_UIN / MICROINCH_PER_UM  # ≈ 1.27 µm
ROUGHNESS_CLIP_UIN = 45.0  # numerical guard only: C_R <= 10

# The same C3 for SI inputs (w [N/m], eta0 [Pa s], Vs, Ve [m/s]); ≈ 2.9662e-2.
KELLEY_C3_SI = KELLEY_C3_US * (LBF_PER_N / INCH_PER_M) / (CENTIPOISE_PER_PA_S * INCH_PER_M**3)

MU_CAP_DEFAULT = 0.15
TINY = 1e-30  # floor for the positive quantities under the logarithm


def roughness_factor(roughness_um, xp=numpy):
    r"""Benedict–Kelley roughness factor $C_R = 50/(50 - S)$, with $S$ in micro-inches.

    **Arguments:**

    - `roughness_um`: average RMS roughness of the two surfaces, `(Rq1 + Rq2)/2` [µm]; scalar
      or array. It is clipped to `[0, ROUGHNESS_CLIP_UIN / MICROINCH_PER_UM]` (about 1.14 µm).
    - `xp`: array namespace (`numpy` or `jax.numpy`).

    **Returns:** `C_R` [-], which is at least 1 and has the shape of `roughness_um`.
    """
    s_uin = xp.clip(xp.asarray(roughness_um) * MICROINCH_PER_UM, 0.0, ROUGHNESS_CLIP_UIN)
    return ROUGHNESS_LIMIT_UIN / (ROUGHNESS_LIMIT_UIN - s_uin)


def kelley_lemanski_magnitude(
    vs_abs_m_per_s,
    ve_m_per_s,
    load_per_width_N_per_m,
    viscosity_Pa_s,
    roughness_um,
    xp=numpy,
    *,
    mu_cap=MU_CAP_DEFAULT,
    c1=KELLEY_C1,
    c3_us=KELLEY_C3_US,
):
    r"""Unsigned Benedict–Kelley friction coefficient from SI inputs.

    $|\mu| = \mathrm{clip}\big(c_1 C_R \log_{10}(c_3 W/(\eta_0 V_s V_e^2)),\ 0,\ \mu_{cap}\big)$,
    evaluated in the original units (lb/in, cP, in/s, µin) after converting the SI inputs.
    Pure, has no branches on values, broadcasts, and works with `jax.numpy`, `jit` and `grad`.

    **Arguments:**

    - `vs_abs_m_per_s`: sliding speed `|V1 - V2|` [m/s] (its `abs` is taken again, to be safe).
    - `ve_m_per_s`: sum (entraining) velocity `V1 + V2` [m/s] -- the sum, not the mean.
    - `load_per_width_N_per_m`: normal load per unit face width on this contact [N/m].
    - `viscosity_Pa_s`: dynamic viscosity of the oil at the inlet temperature [Pa s].
    - `roughness_um`: average RMS roughness `(Rq1 + Rq2)/2` [µm], below 1.27 µm.
    - `xp`: array namespace (`numpy` or `jax.numpy`).
    - `mu_cap`: upper clip on the magnitude [-] (default 0.15, the boundary-friction level).
    - `c1`, `c3_us`: the law's coefficients in the original units (defaults: Benedict & Kelley
      0.0127 and 3.17e8); provided for refitted variants.

    **Returns:** `|mu|` [-] in `[0, mu_cap]`, broadcast over the inputs. The caller multiplies
    it by `sgn(Vs)`.
    """
    # SI -> original units (lb/in, cP, in/s)
    w_lb_per_in = xp.asarray(load_per_width_N_per_m) * (LBF_PER_N / INCH_PER_M)
    eta_cp = xp.asarray(viscosity_Pa_s) * CENTIPOISE_PER_PA_S
    vs_in_per_s = xp.abs(xp.asarray(vs_abs_m_per_s)) * INCH_PER_M
    ve_in_per_s = xp.abs(xp.asarray(ve_m_per_s)) * INCH_PER_M

    # log10 of the argument as a sum of logs: no overflow or underflow, finite gradients
    log_arg = (
        xp.log10(c3_us)
        + xp.log10(xp.maximum(w_lb_per_in, TINY))
        - xp.log10(xp.maximum(eta_cp, TINY))
        - xp.log10(xp.maximum(vs_in_per_s, TINY))
        - 2.0 * xp.log10(xp.maximum(ve_in_per_s, TINY))
    )
    mu = c1 * roughness_factor(roughness_um, xp=xp) * log_arg
    return xp.clip(mu, 0.0, mu_cap)
