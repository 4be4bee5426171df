r"""Cost of one continuation point: wall time, evaluations and corrector iterations per point.

Two curves, each run once to compile and then ``--repeats`` times (median of ``time.perf_counter``):

- ``duffing``: ``x'' + 0.02 x' + x + 0.1 x^3 = 0.05 cos wt``, H=7, N=64, w 0.5 -> 2 (the curve of
  ``tests/test_continuation.py``: ``PseudoArclength()``, tolerance 1e-10);
- ``gear``: the reference pair as configured in ``examples/paper_table1.toml`` (LTV, H=32, N=256,
  tolerance 1e-9), 12000 -> 15000 rpm, with :func:`hbgear.engine.hb.residual_functions`
  and :func:`~hbgear.engine.continuation.sweep_method`.

The residual functions are wrapped with call counters (the wrappers cost ~1 us per call); the
same wrapped callables are passed to every run of a version (``jit_step`` then traces once, in
the compiling run). The versions take turns within each round, since the machine's load drifts.
``--baseline PATH`` also runs another version of ``hbgear.engine.continuation`` on the same
problems -- a single module file (the one before it became a package: ``git show
32b9ddc:hbgear/engine/continuation.py > /tmp/before.py``) or a copy of the package's directory
(``git archive REV hbgear/engine/continuation | tar -x -C /tmp/before``, then
``/tmp/before/hbgear/engine/continuation``): each variant of it runs just before the same
variant of the current version, and the two are compared (time ratio of the medians; max |z
diff| over points, when the two runs store the same number of points). Variants: ``default``,
``chord`` (``PseudoArclength(chord=True)``) and ``jit`` (``jit_step=True``) -- see ``--variants``.

Run: ``python benchmarks/bench_continuation_step.py [--baseline PATH] [--repeats 3]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # measure this checkout, not an installed hbgear
CONFIG = ROOT / "examples" / "paper_table1.toml"


def load_module(path):
    """The module file or package directory at `path`, as a sibling of hbgear.engine.continuation
    (so that its relative imports resolve to this checkout's engine)."""
    path = Path(path)
    name = "hbgear.engine._continuation_baseline"
    if path.is_dir():
        spec = importlib.util.spec_from_file_location(name, path / "__init__.py",
                                                      submodule_search_locations=[str(path)])
    else:
        spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


class Counted:
    def __init__(self, f):
        self.f, self.calls = f, 0

    def __call__(self, *args):
        self.calls += 1
        return self.f(*args)


def duffing_problem():
    import jax.numpy as jnp

    from hbgear.engine.hb import HarmonicBalance
    from hbgear.engine.system import Duffing

    hb, system = HarmonicBalance(1, 7, 1, 64), Duffing(damping=0.02, stiffness=1.0, cubic=0.1, forcing=0.05)

    def rj(z, p):
        return hb.residual_and_jacobians(jnp.asarray(z), p, system)

    def r(z, p):
        return hb.residual(jnp.asarray(z), p, system)

    def method(module, **kw):
        return module.PseudoArclength(**kw)

    return dict(name="duffing H=7, w 0.5 -> 2", rj=rj, r=r, z0=np.zeros(hb.size), p0=0.5, p1=2.0, tol=1e-10,
                method=method, max_points=2000, hb=hb, system=system)


def gear_problem():
    from hbgear import build_model, load_config
    from hbgear.engine.hb import residual_functions
    from hbgear.engine.continuation import sweep_method
    from hbgear.engine.hb import HarmonicBalance
    from hbgear.gear.solve import rpm_to_rad_s, solve_periodic
    from hbgear.gear.system import GearSystem

    cfg = load_config(CONFIG, [])
    model = build_model(cfg)
    H, N, tol = cfg.solver.harmonics, cfg.solver.time_samples, cfg.solver.tolerance
    w0, w1 = rpm_to_rad_s(12000.0), rpm_to_rad_s(15000.0)
    start = solve_periodic(model, w0, harmonics=H, samples=N, tolerance=tol)
    hb, system = HarmonicBalance(model.ndof, H, 1, N), GearSystem(model)
    rj3, r3, fixed = residual_functions(hb, system)

    def rj(z, p):  # bound here: the versions compared need not know continuation's `args`
        return rj3(z, p, *fixed)

    def r(z, p):
        return r3(z, p, *fixed)

    def method(module, **kw):
        base = sweep_method(w0, w1)
        known = {f.name for f in dataclasses.fields(module.PseudoArclength)}
        fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(base) if f.name in known}
        return module.PseudoArclength(**{**fields, **kw})

    return dict(name=f"gear pair LTV H={H} N={N}, 12000 -> 15000 rpm", rj=rj, r=r, z0=np.asarray(start.z), p0=w0, p1=w1,
                tol=tol, method=method, max_points=4000, hb=hb, system=system)


def run_once(module, prob, method_kw, rj, r):
    rj.calls = r.calls = 0
    method = prob["method"](module, **method_kw)
    a = time.perf_counter()
    branch = module.continuation(rj, r, prob["z0"], prob["p0"], prob["p1"], method, tolerance=prob["tol"],
                                 max_points=prob["max_points"], progress=False)
    return time.perf_counter() - a, branch, rj.calls, r.calls


def measure(runs, prob, repeats):
    """Each version once to compile, then `repeats` rounds in turn (the machine's load drifts).
    The same callables are passed every time, as a caller that runs several curves would."""
    out = {}
    for label, module, kw in runs:
        rj, r = Counted(prob["rj"]), Counted(prob["r"])
        first, _, _, _ = run_once(module, prob, kw, rj, r)
        out[label] = dict(first=first, times=[], fns=(rj, r))
    for _ in range(repeats):
        for label, module, kw in runs:
            res = out[label]
            t, branch, n_rj, n_r = run_once(module, prob, kw, *res["fns"])
            n = len(branch)
            res["times"].append(t)
            res.update(branch=branch, points=n, rj_per_point=n_rj / n, r_per_point=n_r / n,
                       iterations=float(np.mean(branch.iterations)), rejected=branch.rejected)
    for res in out.values():
        res["median"] = statistics.median(res["times"])
    return out


def compare(a, b):
    if len(a) != len(b):
        return f"different point counts ({len(a)} vs {len(b)})"
    dz = float(np.max(np.abs(a.z - b.z)))
    dp = float(np.max(np.abs(a.p - b.p)))
    dt = float(np.max(np.abs(a.tangent_p - b.tangent_p)))
    return f"same {len(a)} points: max|dz| {dz:.1e}, max|dp| {dp:.1e}, max|d tangent_p| {dt:.1e}"


VARIANTS = {"default": {}, "chord": {"chord": True}, "jit": {"jit_step": True}}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", help="another continuation module file or package directory to run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--problems", default="duffing,gear")
    parser.add_argument("--variants", default="default,chord,jit")
    args = parser.parse_args(argv)
    import hbgear.engine.continuation as current

    versions = [("", current)]
    if args.baseline:  # each variant of the baseline runs just before the same variant of this version
        versions.insert(0, ("baseline ", load_module(args.baseline)))
    runs = []
    for v in args.variants.split(","):
        kw = VARIANTS[v]
        for prefix, module in versions:
            if set(kw) <= {f.name for f in dataclasses.fields(module.PseudoArclength)}:
                runs.append((prefix + v, module, kw))
            else:
                print(f"(variant {v} not available in {prefix or 'this version'})")
    problems = {"duffing": duffing_problem, "gear": gear_problem}
    for key in args.problems.split(","):
        prob = problems[key]()
        print(f"\n== {prob['name']} (median of {args.repeats} runs after a compiling run)")
        print(f"{'version':17s} {'points':>6s} {'ms/point':>9s} {'runs [s]':>22s} {'first [s]':>9s} "
              f"{'(R,J,Jp)/pt':>11s} {'R/pt':>6s} {'iter/pt':>7s} {'rejected':>8s}")
        results = measure(runs, prob, args.repeats)
        for label, res in results.items():
            runs_s = " ".join(f"{t:.2f}" for t in res["times"])
            print(f"{label:17s} {res['points']:6d} {1e3 * res['median'] / res['points']:9.2f} {runs_s:>22s} "
                  f"{res['first']:9.2f} {res['rj_per_point']:11.2f} {res['r_per_point']:6.2f} {res['iterations']:7.2f} "
                  f"{res['rejected']:8d}")
        for label, res in results.items():
            ref = results.get("baseline " + label)
            if ref is not None:
                print(f"  {label} vs baseline: time per run {res['median'] / ref['median']:.3f}x (medians); "
                      f"{compare(ref['branch'], res['branch'])}; status {res['branch'].status.name}, "
                      f"folds at {np.round(res['branch'].fold_p, 9)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
