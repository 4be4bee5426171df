"""The suite compiles with XLA's code generation at optimisation level 0 (``tests/conftest.py``);
users run at JAX's default, with XLA's LLVM IR emitters (:func:`hbgear.runtime.fast_compilation`).
One command that goes through the compiled continuation, Hill's method along the curve, the
period-doubling search and the variational monodromy, run three ways (the suite's settings, the
product's, the product's with XLA's own fusion emitters): the same curve to rounding."""

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from conftest import TEST_XLA_FLAGS

from hbgear import cli

ROOT = Path(__file__).resolve().parents[1]
#: NLTV (arctan) across the example's period doublings at 5270 and 5380 rpm: 87 points.
ARGS = ["frc", str(ROOT / "examples" / "paper_table1.toml"), "--set", "friction.model=NLTV", "--set",
        "friction.law=arctan", "--set", "sweep.speed_rpm_start=5000", "--set", "sweep.speed_rpm_stop=5800"]


def _table(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array(rows[1:], dtype=float)


def test_the_product_settings_give_the_suites_curve(tmp_path):
    env = dict(os.environ, XLA_FLAGS=os.environ.get("XLA_FLAGS", "").replace(TEST_XLA_FLAGS, "").strip())
    assert "--xla_backend_optimization_level" not in env["XLA_FLAGS"]
    assert "xla_cpu_use_fusion_emitters" not in env["XLA_FLAGS"]  # the command's runtime adds it
    runs = {"product": env, "fusion_emitters": dict(env, HBGEAR_XLA_EMITTERS="default")}
    for out, run_env in runs.items():
        product = subprocess.run([sys.executable, "-m", "hbgear", *ARGS, "--out", str(tmp_path / out)],
                                 env=run_env, capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert product.returncode == 0, product.stderr
    assert cli.main([*ARGS, "--out", str(tmp_path / "suite")]) == 0
    for other in runs:
        for name, loose in (("frc.csv", "residual"), ("floquet.csv", None)):
            head, a = _table(tmp_path / other / name)
            head_b, b = _table(tmp_path / "suite" / name)
            assert head == head_b and a.shape == b.shape and len(a) > 80
            keep = [k for k, h in enumerate(head) if h != loose]
            np.testing.assert_allclose(b[:, keep], a[:, keep], rtol=1e-9, atol=1e-12)
            if loose:  # max|R| at the converged points: rounding of numbers below the tolerance
                assert np.all(b[:, head.index(loose)] <= 1e-9) and np.all(a[:, head.index(loose)] <= 1e-9)
    summaries = [json.loads((tmp_path / d / "frc.json").read_text()) for d in ("suite", *runs)]
    doublings = [np.array([c["speed_rpm"] for c in s["period_doubling"]]) for s in summaries]
    assert len(doublings[0]) == 2
    for other in doublings[1:]:
        np.testing.assert_allclose(other, doublings[0], rtol=1e-9)
