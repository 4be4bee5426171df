"""Per-pair tooth contact (MODEL.md section 9) at rest and at crawling speed: the model's static
state against a scalar root solve per phase, and the quasi-static limit of harmonic balance against
the library's loaded static TE (with its order of convergence in H)."""

import numpy as np
import pytest
from pair_contact_models import iso_relief_model
from scipy.optimize import brentq

from hbgear.gear.contact import static_transmission_error
import hbgear


def test_static_state_is_the_scalar_root_per_phase():
    """The model's static DTE ``delta_s(s)`` against an independent root solve per phase:
    ``sum_j k_j max(D - e_j, 0) = N`` by Brent's method on the model's pair stiffness and relief."""
    model, contact = iso_relief_model(150.0)
    s = np.linspace(0.0, 1.0, 41, endpoint=False)
    mine = np.asarray(model.static_dte(s, 100.0))
    n = float(model.normal_load_N)
    for phase, delta in zip(s, mine):
        xi = contact.geometry.contact_start_m + contact.geometry.base_pitch_m * (phase + np.arange(2))
        inside = phase + np.arange(2) < float(model.contact_ratio)
        k = np.where(inside, contact.pair_stiffness.stiffness(xi - contact.geometry.contact_start_m), 0.0)
        e = contact.modification.deviation(contact.geometry, xi)
        root = brentq(lambda d: np.sum(k * np.maximum(d - e, 0.0)) - n, 0.0, 1e-3, xtol=1e-18, rtol=1e-15)
        assert delta == pytest.approx(root, rel=1e-12)


def test_quasi_static_limit_is_the_loaded_static_te_and_converges_in_h():
    """At 20 rpm the HB DTE tends to the library's loaded static TE (:func:`static_transmission_error`),
    its Fourier orders 0..8 compared by a Gauss rule between the breakpoints (the static TE is
    smooth there). Frictionless (friction moments change the static balance) with constant torques
    (the spring boundary's soft mode lies below this mesh frequency).

    Expected size of the difference: the dynamic correction of order ``n`` is
    ``~ 2 zeta n r + (n r)^2`` with ``r = w_m/w_n ~ 2e-3`` (<= 4e-4 of that order's amplitude,
    far below the p2p), and the truncation: this pair's static TE jumps at pair entry and exit (the
    relief, 24 um, is a little less than the single-pair deflection at 226 N m, so the entering
    tooth loads at once) and ``k(s)`` jumps there too. HB makes the low orders of
    ``k(s) (x - D(s))`` vanish with ``x`` of degree ``H``; ``D``'s unresolved orders ``m > H``
    (``D_m ~ 1/m``) feed the low orders through ``k``'s (``k_m ~ 1/m``): the error is
    ``sum_{m > H} 1/m^2 ~ 1/H``, order 1 in ``H``. Observed over H = 32, 64, 128: order ~1,
    and below 2e-4 of the p2p at H = 128."""
    from hbgear.engine.quadrature import mesh_period_rule
    from hbgear.gear.friction import NoFriction

    model, contact = iso_relief_model(226.0, friction=NoFriction(), boundary="torques")
    f, w = mesh_period_rule(model.phase_breakpoints(), 64)

    def static(phases=None):
        return static_transmission_error(contact.geometry, contact.pair_stiffness, float(model.normal_load_N),
                                         modification=contact.modification, phases=phases).delta_m

    basis = np.exp(-2j * np.pi * np.arange(9)[:, None] * f[None])
    target, p2p = basis @ (w * static(f)), np.ptp(static())
    errors = []
    for harmonics in (32, 64, 128):
        sol = hbgear.solve(model, speed_rpm=20.0, harmonics=harmonics, stability=False)
        errors.append(np.max(np.abs(basis @ (w * np.asarray(sol.state_at(f)[0][0])) - target)) / p2p)
    order = -np.diff(np.log(errors)) / np.log(2.0)
    assert np.all((order > 0.8) & (order < 1.3)), (errors, order)
    assert errors[-1] < 2e-4
