"""Per-pair tooth contact (MODEL.md section 9), stability on the relieved ISO pair: Hill's method,
the variational equations and the exact monodromy in the linear regime, and continuation through
the contact-loss folds near the resonance with the stability alternating between them."""

import math

import numpy as np
from pair_contact_models import iso_relief_model

import hbgear
from hbgear.gear.solve import solve_periodic


def test_hill_variational_and_exact_monodromy_on_a_relieved_pair():
    """Relief for 226 N m run at 300 N m: every pair of the path stays loaded, so the relieved
    model is in its linear regime and its variational equations are those of the closed mesh
    (exact monodromy of the linear equivalent). Hill's method, the variational equations along
    the HB solution and the exact monodromy agree."""
    from hbgear.gear.monodromy import floquet_multipliers
    from hbgear.gear.system import GearSystem, linear_equivalent

    model, _ = iso_relief_model(300.0)
    omega = 3000.0 * math.pi / 30
    sol = solve_periodic(model, omega, harmonics=48)
    assert not model.is_linear and linear_equivalent(model, sol) is not None
    var = np.sort_complex(floquet_multipliers(model, omega, solution=sol, method="variational"))
    exact = np.sort_complex(floquet_multipliers(linear_equivalent(model, sol), omega, method="monodromy"))
    assert np.max(np.abs(var - exact)) < 1e-7
    # Hill truncates a coefficient k(t) that jumps at pair entry and exit: it converges in H
    # (at H = 48 on `sol` itself: the same solve)
    hill = [np.sort_complex(floquet_multipliers(model, omega, solution=s, method="hill"))
            for s in (sol, solve_periodic(model, omega, harmonics=96))]
    errors = [np.max(np.abs(m - exact)) for m in hill]
    assert errors[0] < 3e-5 and errors[1] < 0.7 * errors[0], errors


#: Around the resonance of examples/iso_tip_relief.toml (H = 12): folds at 9487, 9185, 9556 and 9136 rpm.
FOLD_RANGE_RPM = (9000.0, 9800.0)


def test_continuation_through_the_contact_loss_folds_of_a_relieved_pair():
    """The relieved iso pair near its resonance: partial contact loss softens the curve, which
    folds at 9487 rpm, runs back on an unstable branch to 9185 rpm, up a stable one to 9556 rpm
    and back on an unstable one to 9136 rpm onto the lower stable branch. The continuation passes
    the four folds to the end of the range, every point within the tolerance, stability
    alternating. (Before the arclength sized the soft output spring's mean wind-up, which follows
    the pairs' mean friction torque 5e5 times more than the mesh, the steps near the fold were
    ~0.1 rpm at H = 32 and the run stopped on the first unstable branch at 9394 rpm.)"""
    model, _ = iso_relief_model(226.0)
    curve = hbgear.frequency_response(model, speed_rpm=FOLD_RANGE_RPM, harmonics=12, samples=256,
                                      max_points=400, period_doubling=False)
    assert curve.success
    folds = [int(f["index"]) for f in curve.fold_records]
    assert np.allclose(curve.folds, [9487.2, 9185.3, 9555.6, 9135.6], atol=1.0), curve.folds
    assert curve.speed_rpm[-1] == FOLD_RANGE_RPM[1]
    assert np.max(np.asarray(curve.residual)) <= 1e-9
    stable = np.asarray(curve.stable, dtype=bool)
    edges = [0, *folds, len(stable)]
    for k in range(5):  # stable, unstable, stable, unstable, stable between the folds
        inner = stable[edges[k] + 2:edges[k + 1] - 1]
        assert len(inner) and (inner.all() if k % 2 == 0 else not inner.any()), k
