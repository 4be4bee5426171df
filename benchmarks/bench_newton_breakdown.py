r"""Where the time of a continuation step goes, and what faster variants would save.

Part 1 -- **breakdown** of :func:`hbgear.engine.continuation.continuation` on the NLTV reference pair
(``examples/paper_table1.toml``, ``friction.model = NLTV``, ``law = arctan``, ``H = 32``,
``N = 256``) over a part of the speed range. The residual functions passed in are wrapped with
``time.perf_counter`` (including ``block_until_ready`` and the copy to numpy), and, for the
duration of the run only, ``scipy.linalg.lu_factor``/``lu_solve``/``solve`` are wrapped the
same way. Python overhead = wall time - evaluations - linear algebra. The floor is one dense LU
(+ solve) of the bordered Jacobian, size ``ndof (2H+1) + 1``, per corrector step of this (Newton)
run. The same range is then run with the compiled correctors (``jit_step=True``, Newton and
``chord=True``; ``COMPILED_REPEATS`` timed runs after a compiling one), each run's time per point
set against the floor measured just before it (the LU's time moves by 2x between runs on a
shared machine); the ratio reported is the median of those pairs.

Part 2 -- **pieces** of one evaluation (median of repeated calls after compilation):
residual, ``(R, J)``, ``(R, J, dR/dp)``, the linear operator alone, the AFT part alone.

Part 3 -- **prototypes** (here only, hbgear is not modified), each checked against hbgear's
own result:

- ``toeplitz J``: the AFT part of the Jacobian as convolution matrices of the sampled pointwise
  derivatives ``dQ_nl/dq``, ``dQ_nl/dq'`` (one ``rfft`` each, :func:`hbgear.engine.fourier.convolution_matrix`)
  instead of ``jax.jacfwd`` pushing ``ndof (2H+1)`` tangents through the whole residual.
- ``fused (R, J, dR/dp)``: one ``jax.jvp`` in ``p`` gives ``R``, ``dR/dp`` and the operator
  (built once, primal and tangent together) + the Toeplitz Jacobian.
- ``cached operator``: the periodic-coefficient matrices computed once per geometry (valid when
  they do not depend on ``p``, checked numerically here), ``L(p) = M (x) D(w)^2 + K + C D(w)``.

Run: ``python benchmarks/bench_newton_breakdown.py [--quick]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import statistics
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # measure this checkout, not an installed hbgear
CONFIG = ROOT / "examples" / "paper_table1.toml"
OVERRIDES = ["friction.model=NLTV", "friction.law=arctan"]
H, SAMPLES, TOL = 32, 256, 1e-9


#: Timed runs of each compiled corrector; each is set against the LU floor measured just before it.
COMPILED_REPEATS = 4


def median_ms(f, n=30):
    import jax

    jax.block_until_ready(f())
    times = []
    for _ in range(n):
        a = time.perf_counter()
        jax.block_until_ready(f())
        times.append(time.perf_counter() - a)
    return 1e3 * statistics.median(times)


class Timer:
    def __init__(self):
        self.total, self.calls = {}, {}

    def wrap(self, name, f):
        def g(*args, **kwargs):
            a = time.perf_counter()
            out = f(*args, **kwargs)
            self.total[name] = self.total.get(name, 0.0) + time.perf_counter() - a
            self.calls[name] = self.calls.get(name, 0) + 1
            return out

        return g


@contextmanager
def timed_linalg(timer):
    import scipy.linalg

    saved = {k: getattr(scipy.linalg, k) for k in ("lu_factor", "lu_solve", "solve")}
    try:
        for k, f in saved.items():
            setattr(scipy.linalg, k, timer.wrap(f"linalg.{k}", f))
        yield
    finally:
        for k, f in saved.items():
            setattr(scipy.linalg, k, f)


def setup():
    from hbgear.build import build_model
    from hbgear.config import load_config
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.system import GearSystem

    model = build_model(load_config(CONFIG, OVERRIDES))
    return model, HarmonicBalance(model.ndof, H, 1, SAMPLES), GearSystem(model)


# ----------------------------------------------------------------------------- part 1
def breakdown(model, hb, system, rpm0, rpm1):
    import jax

    from hbgear.engine.hb import residual_functions
    from hbgear.engine.continuation import sweep_method
    from hbgear.engine.continuation import continuation
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

    w0, w1 = rpm_to_rad_s(rpm0), rpm_to_rad_s(rpm1)
    start = solve_periodic(model, w0, harmonics=H, samples=SAMPLES, tolerance=TOL)
    rjp, res, fixed = residual_functions(hb, system)
    timer = Timer()

    def rjp_np(z, p):
        return tuple(np.asarray(x) for x in jax.block_until_ready(rjp(z, p, *fixed)))

    def res_np(z, p):
        return np.asarray(jax.block_until_ready(res(z, p, *fixed)))

    rjp_np(start.z, w0), res_np(start.z, w0)  # compiled
    with timed_linalg(timer):
        a = time.perf_counter()
        branch = continuation(timer.wrap("eval (R,J,dR/dp)", rjp_np), timer.wrap("eval R (line search)", res_np),
                              start.z, w0, w1, dataclasses.replace(sweep_method(w0, w1), jit_step=False, chord=False),
                              max_points=6000, tolerance=TOL, progress=False)
        wall = time.perf_counter() - a
    size = hb.size + 1
    a_mat = np.random.default_rng(0).standard_normal((size, size))
    import scipy.linalg

    def floor_ms():
        return median_ms(lambda: scipy.linalg.lu_solve(scipy.linalg.lu_factor(a_mat, check_finite=False), a_mat[0],
                                                       check_finite=False), 300)

    lu_ms = floor_ms()
    steps = timer.calls.get("linalg.lu_factor", 0)
    steps_per_point = steps / len(branch)
    compiled = {}
    for label, chord in (("compiled Newton", False), ("compiled chord", True)):
        method = dataclasses.replace(sweep_method(w0, w1), jit_step=True, chord=chord)
        times, ratios = [], []
        for k in range(COMPILED_REPEATS + 1):  # the first run compiles the corrector
            floor = floor_ms() if k else None  # measured next to each timed run: the pair's ratio
            a = time.perf_counter()
            run = continuation(rjp, res, start.z, w0, w1, method, max_points=6000, tolerance=TOL, progress=False,
                               args=fixed)
            times.append(time.perf_counter() - a)
            if k:
                ratios.append(1e3 * times[-1] / len(run) / (steps_per_point * floor))
        compiled[label] = {"wall": statistics.median(times[1:]), "points": len(run),
                           "iterations": int(np.sum(run.iterations)), "rejected": run.rejected,
                           "floor_ratio": statistics.median(ratios), "floor_ratios": ratios}
    return {"wall": wall, "points": len(branch), "timer": timer, "lu_ms": lu_ms, "steps": steps,
            "iterations": int(np.sum(branch.iterations)), "rejected": branch.rejected, "size": size,
            "compiled": compiled}


# ----------------------------------------------------------------------------- parts 2 and 3
def prototypes(model, hb, system):
    import jax
    import jax.numpy as jnp

    from hbgear.engine import fourier
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic

    w = rpm_to_rad_s(13000.0)
    z = jnp.asarray(solve_periodic(model, w, harmonics=H, samples=SAMPLES, tolerance=TOL).z)
    quad = hb.prepare(system)._replace(frozen=None)  # the full construction (no frozen blocks), as before the caching
    n, B = hb.ndof, hb.block
    xs, fs = system.displacement_scale, system.force_scale
    out = {}

    out["residual"] = median_ms(lambda: hb.residual(z, w, system))
    out["(R, J)"] = median_ms(lambda: hb.residual_and_jacobian(z, w, system))
    out["(R, J, dR/dp)"] = median_ms(lambda: hb.residual_and_jacobians(z, w, system))
    prepared = hb.prepare(system)  # with the speed-independent pieces (what hbgear uses)
    response_jit = jax.jit(lambda x, p, s: hb._linear_response(x, p, s, prepared))
    out["L x - F from the frozen pieces (hbgear now)"] = median_ms(lambda: response_jit(z * xs, w, system))
    forcing_jit = jax.jit(lambda p, s: hb._forcing(s, p, prepared))
    out["  of which the forcing from its pieces"] = median_ms(lambda: forcing_jit(w, system))
    windup_jit = jax.jit(lambda p, s: s.model.static_state(p, jnp)[1])
    out["    of which the spring wind-up u_s(w)"] = median_ms(lambda: windup_jit(w, system))
    nl_jacobian_jit = jax.jit(lambda x, p, s: hb._nonlinear_jacobian(x, 0.0, p, s)[:2])
    out["AFT Jacobian blocks (sampled derivatives)"] = median_ms(lambda: nl_jacobian_jit(z * xs, w, system))
    op_jit = jax.jit(lambda p, s: hb.linear_operator(s, p, quad))
    out["linear operator, full construction (before)"] = median_ms(lambda: op_jit(w, system))
    coeff_jit = jax.jit(lambda p, s: hb._periodic_coefficients(s, p, quad))
    out["  of which periodic coefficients (quadrature)"] = median_ms(lambda: coeff_jit(w, system))
    nl_jit = jax.jit(lambda x, p, s: hb._nonlinear(x, hb._velocity(x, s, p), 0.0, p, s))
    out["AFT nonlinear term alone"] = median_ms(lambda: nl_jit(z * xs, w, system))
    op = op_jit(w, system)
    jac_fixed = jax.jit(lambda zz, p, s, o: jax.jacfwd(hb._residual)(zz, p, s, quad, o))
    out["jacfwd of the residual, operator given"] = median_ms(lambda: jac_fixed(z, w, system, op))

    # --- toeplitz Jacobian of the AFT part ------------------------------------------------
    def nl_jacobian(zz, p, s):
        x = zz * xs
        v = hb._velocity(x, s, p)
        q = fourier.synthesize(x.reshape(n, B), H, SAMPLES, jnp)
        qd = fourier.synthesize(v.reshape(n, B), H, SAMPLES, jnp)
        phase = jnp.mod(jnp.arange(SAMPLES) / SAMPLES, 1.0)

        def pointwise(si, qi, qdi):
            f = lambda a, b: s.force(si[None], a[:, None], b[:, None], p, "nonlinear", 0.0, jnp)[:, 0]
            return jax.jacfwd(f, argnums=(0, 1))(qi, qdi)

        dq, dqd = jax.vmap(pointwise)(phase, q.T, qd.T)  # (N, n, n) each
        def conv(g):  # (N, n, n) -> (n, n, B, B)
            c = jnp.fft.rfft(jnp.transpose(g, (1, 2, 0)), axis=-1)[..., : 2 * H + 1] / SAMPLES
            return fourier.convolution_matrix(c, H, jnp)

        d = fourier.derivative_matrix(H, hb.base_frequency(s, p), jnp)
        blocks = conv(dq) + conv(dqd) @ d[None, None]
        return hb._flatten(blocks)

    def rj_toeplitz(zz, p, s, o):
        r = hb._residual(zz, p, s, quad, o)
        return r, (o[0] - nl_jacobian(zz, p, s)) * (xs / fs)

    rj_t = jax.jit(rj_toeplitz)
    r_ref, j_ref = hb.residual_and_jacobian(z, w, system)
    r_t, j_t = rj_t(z, w, system, op)
    out["toeplitz (R, J), operator given"] = median_ms(lambda: rj_t(z, w, system, op))
    out["_check toeplitz J max|diff| / max|J|"] = float(jnp.max(jnp.abs(j_t - j_ref)) / jnp.max(jnp.abs(j_ref)))

    def fused(zz, p, s):
        def f(pp):
            o = hb.linear_operator(s, pp, quad)
            return hb._residual(zz, pp, s, quad, o), o[0]

        (r, lin), (rp, _) = jax.jvp(f, (p,), (jnp.ones_like(p),))
        return r, (lin - nl_jacobian(zz, p, s)) * (xs / fs), rp

    fused_jit = jax.jit(fused)
    ref = hb.residual_and_jacobians(z, w, system)
    got = fused_jit(z, w, system)
    out["fused (R, J, dR/dp): one jvp in p + toeplitz J"] = median_ms(lambda: fused_jit(z, w, system))
    out["_check fused dR/dp max|diff| / max|dR/dp|"] = float(jnp.max(jnp.abs(got[2] - ref[2])) / jnp.max(jnp.abs(ref[2])))

    # --- cached periodic coefficients -----------------------------------------------------
    c1, c2 = coeff_jit(w, system), coeff_jit(1.37 * w, system)
    k_indep = all(float(jnp.max(jnp.abs(a - b))) <= 1e-12 * float(jnp.max(jnp.abs(a)) + 1e-300) for a, b in zip(c1[1:], c2[1:]))
    out["_check K, C coefficients independent of speed"] = bool(k_indep)
    k_conv = fourier.convolution_matrix(c1[1], H, jnp)
    c_conv = fourier.convolution_matrix(c1[2], H, jnp)
    mass = system.mass_matrix(w, jnp)

    def cached_operator(p, s):
        d = fourier.derivative_matrix(H, hb.base_frequency(s, p), jnp)
        blocks = mass[:, :, None, None] * (d @ d)[None, None] + k_conv + c_conv @ d[None, None]
        return hb._flatten(blocks)

    def fused_cached(zz, p, s, forcing, dforcing):
        # forcing (and its p-derivative) would be refreshed cheaply per point (u_static(p) only)
        def f(pp):
            lin = cached_operator(pp, s)
            return hb._residual(zz, pp, s, quad, (lin, forcing + (pp - p) * dforcing, None)), lin

        (r, lin), (rp, _) = jax.jvp(f, (p,), (jnp.ones_like(p),))
        return r, (lin - nl_jacobian(zz, p, s)) * (xs / fs), rp

    (_, forcing, _), (_, dforcing, _) = jax.jvp(lambda pp: hb.linear_operator(system, pp, quad), (w,), (1.0,))
    fc = jax.jit(fused_cached)
    got = fc(z, w, system, forcing, dforcing)
    out["fused with cached K, C (forcing passed in)"] = median_ms(lambda: fc(z, w, system, forcing, dforcing))
    out["_check cached: max|R diff|, max|dR/dp diff| rel"] = (
        float(jnp.max(jnp.abs(got[0] - ref[0]))),
        float(jnp.max(jnp.abs(got[2] - ref[2])) / jnp.max(jnp.abs(ref[2]))))
    residual_cached = jax.jit(lambda zz, p, s, forcing: hb._residual(zz, p, s, quad, (cached_operator(p, s), forcing, None)))
    out["residual with cached K, C (line search)"] = median_ms(lambda: residual_cached(z, w, system, forcing))
    return out


def run(quick=False):
    model, hb, system = setup()
    rpm1 = 5000.0 if quick else 8000.0
    b = breakdown(model, hb, system, 3000.0, rpm1)
    b["range"] = (3000.0, rpm1)
    return b, prototypes(model, hb, system)


def table(b, protos):
    t = b["timer"]
    ev = t.total.get("eval (R,J,dR/dp)", 0.0)
    ls = t.total.get("eval R (line search)", 0.0)
    la = sum(v for k, v in t.total.items() if k.startswith("linalg."))
    py = b["wall"] - ev - ls - la
    pts = b["points"]
    floor = b["steps"] * b["lu_ms"] / 1e3
    lines = [
        f"continuation {b['range'][0]:g} -> {b['range'][1]:g} rpm: {pts} points, {b['iterations']} corrector iterations, "
        f"{b['rejected']} rejected steps; {t.calls.get('eval (R,J,dR/dp)', 0)} (R,J,dR/dp) + "
        f"{t.calls.get('eval R (line search)', 0)} R evaluations; {b['steps']} LU, {t.calls.get('linalg.solve', 0)} solve",
        f"{'piece':40s} {'total [s]':>9s} {'per point [ms]':>14s} {'share':>6s}",
        f"{'(R, J, dR/dp) evaluations':40s} {ev:9.2f} {1e3 * ev / pts:14.2f} {100 * ev / b['wall']:5.1f}%",
        f"{'R evaluations (line search)':40s} {ls:9.2f} {1e3 * ls / pts:14.2f} {100 * ls / b['wall']:5.1f}%",
        f"{'linear algebra (LU, solves, tangent)':40s} {la:9.2f} {1e3 * la / pts:14.2f} {100 * la / b['wall']:5.1f}%",
        f"{'Python overhead (rest)':40s} {py:9.2f} {1e3 * py / pts:14.2f} {100 * py / b['wall']:5.1f}%",
        f"{'total':40s} {b['wall']:9.2f} {1e3 * b['wall'] / pts:14.2f}",
        f"floor: one LU+solve of {b['size']}x{b['size']} = {b['lu_ms']:.3f} ms x {b['steps'] / pts:.2f} steps per point "
        f"= {1e3 * floor / pts:.2f} ms per point; total / floor = {b['wall'] / floor:.0f}x (goal <= 3x)",
    ]
    for label, c in b.get("compiled", {}).items():
        per_point = c["wall"] / c["points"]
        lines.append(f"{label + ' corrector (jit_step)':40s} {c['wall']:9.2f} {1e3 * per_point:14.2f}   "
                     f"{c['points']} points, {c['iterations'] / c['points']:.2f} iterations per point, "
                     f"{c['rejected']} rejected; per point / floor = {c['floor_ratio']:.1f}x (median of "
                     f"{len(c['floor_ratios'])} runs, each against the floor measured just before it: "
                     + ", ".join(f"{x:.1f}" for x in c["floor_ratios"]) + ")")
    lines += [
        "",
        f"{'one evaluation at 13000 rpm (median)':52s} {'ms':>8s}",
    ]
    for k, v in protos.items():
        if k.startswith("_check"):
            lines.append(f"  {k[7:]}: {v}")
        else:
            lines.append(f"{k:52s} {v:8.3f}")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--profile", action="store_true", help="also print the top of a cProfile of the run")
    args = parser.parse_args(argv)
    if args.profile:
        import cProfile
        import pstats

        model, hb, system = setup()
        prof = cProfile.Profile()
        prof.enable()
        breakdown(model, hb, system, 3000.0, 5000.0)
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)
    b, protos = run(args.quick)
    print(table(b, protos))
    return 0


if __name__ == "__main__":
    sys.exit(main())
