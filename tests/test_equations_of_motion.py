"""``GearPairModel.generalized_force`` against an independent derivation of the equations of motion.

``tests/derivation.py`` derives the equations again from energies and virtual work (sympy) and
computes every derived quantity from MODEL.md; nothing there imports ``hbgear``. Here the two
are compared through physical accelerations (``phi_p''``, ``phi_g''``, or ``delta''``), which do
not depend on the coordinates either side uses; :func:`model_view` is the only code that knows
the model's coordinates. Models are built through the public config API.

The friction normal-load rule of MODEL.md §11 is the specification the derivation implements
(no friction without a compressive load; the back flank by the mirror simplification): every case
below, separation and back-flank contact included, must agree.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from hypothesis import Phase, given, settings
from hypothesis import strategies as st

import derivation as dv
from hbgear import build_model, load_config
from hbgear.config import parse_config
from hbgear.errors import ConfigError

RTOL = 1e-12  # relative to the sum of the magnitudes of the terms (derivation.magnitude)
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "paper_table1.toml"
LAWS = ("none", "coulomb", "arctan", "kelley-lemanski")
TRANSLATIONS = ("y_p", "x_p", "y_g", "x_g")


# ------------------------------------------------------------------------------ the adapter

#: Does the model carry the centre translations (MODEL.md §10)? Yes: models built with a
#: ``[bearings]`` section (``Combo.bearings``) get states whose centres move; the rigid-bearing
#: models keep them at zero and :func:`model_view` checks that.
MODEL_HAS_BEARINGS = True


def model_view(model, p: dv.Parameters, s, omega, state):
    """The model's physical accelerations and per-pair friction for a physical `state`.

    The one place that knows the model's coordinates (model.py and gear/dofs.py docstrings):
    boundary ``"torques"``: ``q = (delta,)``; ``"spring"``/``"reaction"``: ``q = (delta, u)``,
    ``u = R_bg (theta_g - theta_g,s)``, ``R_bp theta_p = delta + u + u_s``. The state's rigid
    wind-up ``theta_w`` is taken as the static one (``u_s = R_bg theta_w``, so ``u = R_bg phi_g``).
    On bearings (:func:`_bearing_view`) the translations follow. A rigid-bearing model's state
    has its translations at zero.

    Returns ``(accelerations, pair)``: name -> array (``"delta_rotation"`` -- ``delta''`` with the
    bearings rigid -- or ``"phi_p"``, ``"phi_g"``; on bearings ``"delta"`` and the translations)
    and the per-pair ``mu``, ``normal``, ``vs`` of ``model.pair_friction``."""
    if model.bearings is not None:
        return _bearing_view(model, p, s, omega, state)
    for name in TRANSLATIONS:
        assert not np.any(state[name]) and not np.any(state["d" + name]), "a rigid-bearing model's state"
    rbp, rbg = p.geometry.Rbp, p.geometry.Rbg
    delta = rbp * state["phi_p"] - rbg * state["phi_g"]
    ddelta = rbp * state["dphi_p"] - rbg * state["dphi_g"]
    if model.ndof == 1:
        q, qd = delta[None], ddelta[None]
    else:
        q = np.stack([delta, rbg * state["phi_g"]])
        qd = np.stack([ddelta, rbg * state["dphi_g"]])
    reaction = state.get("reaction", 0.0) if model.boundary == "reaction" else 0.0  # the solver's unknown
    force = np.asarray(model.generalized_force(s, q, qd, omega, u_static=rbg * state.get("windup", 0.0),
                                               reaction=reaction))
    qdd = np.linalg.solve(np.asarray(model.mass_matrix()), force)
    if model.ndof == 1:
        acc = {"delta_rotation": qdd[0]}
    else:
        acc = {"phi_p": (qdd[0] + qdd[1]) / rbp, "phi_g": qdd[1] / rbg}
    pair = model.pair_friction(s, q, qd, omega)
    return acc, {key: np.asarray(pair[key]) for key in ("mu", "normal", "vs")}


def _bearing_view(model, p: dv.Parameters, s, omega, state):
    """:func:`model_view` on bearings (MODEL.md §10, gear/dofs.py): ``q = (delta[, u], y_p, x_p, y_g,
    x_g)`` with ``delta = R_bp phi_p - R_bg phi_g + y_p - y_g`` (the state's translations are total)
    and the translations about the static deflections ``-N/k_py``, ``+N/k_gy``; physically
    ``a_g = u + u_s``, ``a_p = delta + a_g - y_p + y_g``."""
    rbp, rbg, br, n = p.geometry.Rbp, p.geometry.Rbg, p.bearings, p.normal_load
    delta = rbp * state["phi_p"] - rbg * state["phi_g"] + state["y_p"] - state["y_g"]
    ddelta = rbp * state["dphi_p"] - rbg * state["dphi_g"] + state["dy_p"] - state["dy_g"]
    moving = [state["y_p"] + n / br.k_py, state["x_p"], state["y_g"] - n / br.k_gy, state["x_g"]]
    rates = [state["d" + name] for name in TRANSLATIONS]
    rigid = model.boundary == "torques"
    q = np.stack([delta] + ([] if rigid else [rbg * state["phi_g"]]) + moving)
    qd = np.stack([ddelta] + ([] if rigid else [rbg * state["dphi_g"]]) + rates)
    reaction = state.get("reaction", 0.0) if model.boundary == "reaction" else 0.0
    force = np.asarray(model.generalized_force(s, q, qd, omega, u_static=rbg * state.get("windup", 0.0),
                                               reaction=reaction))
    qdd = np.linalg.solve(np.asarray(model.mass_matrix()), force)
    first = 1 if rigid else 2
    acc = {"delta": qdd[0]} | {name: qdd[first + i] for i, name in enumerate(TRANSLATIONS)}
    if not rigid:
        acc |= {"phi_g": qdd[1] / rbg, "phi_p": (qdd[0] + qdd[1] - qdd[2] + qdd[4]) / rbp}
    pair = model.pair_friction(s, q, qd, omega)
    return acc, {key: np.asarray(pair[key]) for key in ("mu", "normal", "vs")}


# ------------------------------------------------------------------------ option combinations


@dataclass(frozen=True)
class Combo:
    coupling: str
    formulation: str
    boundary: str
    backlash: bool
    law: str
    damping: str
    ste: bool
    bearings: bool = False

    @property
    def id(self) -> str:
        return "-".join([self.coupling, self.formulation, self.boundary, "backlash" if self.backlash else "linear",
                         self.law, self.damping, "ste" if self.ste else "no-ste"]
                        + (["bearings"] if self.bearings else []))


def all_combos():
    for coupling in ("LTI", "LTV", "NLTV"):
        for formulation in ("A",) if coupling == "LTI" else ("A", "B"):
            for boundary in ("spring", "reaction") if coupling == "NLTV" else ("torques", "spring", "reaction"):
                for backlash in (False,) if coupling == "LTI" else (False, True):
                    for law in LAWS:
                        for damping in ("constant", "proportional"):
                            for ste in (False, True):
                                yield Combo(coupling, formulation, boundary, backlash, law, damping, ste)


RIGID_COMBOS = tuple(all_combos())
#: every combination on rigid bearings (the 2-DOF model) and on bearings (MODEL.md §10)
COMBOS = RIGID_COMBOS + tuple(replace(c, bearings=True) for c in RIGID_COMBOS)


def config_dict(combo: Combo, rng, *, k_pair_MN_per_m=None) -> dict:
    """A random but physical gear pair with the combination's options (config units)."""
    zp = int(rng.integers(18, 36))
    zg = int(rng.integers(zp, int(2.6 * zp)))
    jp = rng.uniform(4e-4, 3e-3)
    gear = dict(teeth_pinion=zp, teeth_gear=zg, module_mm=rng.uniform(2.0, 5.0),
                pressure_angle_deg=rng.uniform(17.0, 25.0), contact_ratio=rng.uniform(1.25, 1.7),
                face_width_mm=rng.uniform(10.0, 40.0), inertia_pinion_kgm2=jp,
                inertia_gear_kgm2=jp * (zg / zp) ** 4 * rng.uniform(0.7, 1.3))
    if k_pair_MN_per_m is None:
        k_max = rng.uniform(400.0, 900.0)
        k_min = k_max * rng.uniform(0.55, 0.95)
        g = gear["contact_ratio"]
        mesh = dict(k_max_MN_per_m=k_max, k_mean_MN_per_m=k_max * (g - 1) + k_min * (2 - g))
    else:  # per-pair limit: k_max = 2 k1, k_min = k1
        mesh = dict(k_max_MN_per_m=2 * k_pair_MN_per_m, k_min_MN_per_m=k_pair_MN_per_m)
    orders = int(rng.integers(1, dv.STE_ORDERS + 1))
    mesh |= dict(damping_ratio=rng.uniform(0.005, 0.08), damping_model=combo.damping,
                 backlash_um=rng.uniform(5.0, 80.0) if combo.backlash else 0.0,
                 ste_amplitude_um=list(rng.uniform(0.2, 3.0, orders)) if combo.ste else [],
                 ste_phase_deg=list(rng.uniform(0.0, 360.0, orders)) if combo.ste else [])
    friction = dict(law=combo.law, mu0=rng.uniform(0.03, 0.2), v0_m_per_s=rng.uniform(0.002, 0.05),
                    formulation=combo.formulation, model=combo.coupling,
                    viscosity_Pa_s=rng.uniform(0.005, 0.08), roughness_um=rng.uniform(0.1, 1.0),
                    regularization_m_per_s=rng.uniform(0.001, 0.02))
    boundary = dict(output=combo.boundary, stiffness_ratio=10 ** rng.uniform(3.0, 6.0),
                    damping_ratio=rng.uniform(0.02, 0.3))
    out = dict(gear=gear, mesh=mesh, load=dict(torque_pinion_Nm=rng.uniform(60.0, 400.0)),
               friction=friction, boundary=boundary)
    if combo.bearings:  # every direction its own stiffness; the pinion's mass given, the gear's a solid disk
        out["bearings"] = dict(pinion_loa_stiffness_MN_per_m=rng.uniform(100.0, 900.0),
                               pinion_oloa_stiffness_MN_per_m=rng.uniform(100.0, 900.0),
                               gear_stiffness_MN_per_m=rng.uniform(100.0, 900.0),
                               gear_oloa_stiffness_MN_per_m=rng.uniform(100.0, 900.0),
                               damping_ratio=rng.uniform(0.005, 0.1), mass_pinion_kg=rng.uniform(0.5, 3.0))
    return out


def derivation_bearings(data: dict) -> dv.Bearings:
    """The derivation's bearing numbers from a config dict's ``[bearings]`` (INTERFACE.md): each
    direction's stiffness (its own key, else the gear's), ``c = 2 zeta sqrt(k m)``, a missing mass
    that of a solid disk ``m = 2 J / r_pitch^2``."""
    b, gear = data["bearings"], data["gear"]
    values = {}
    for end, tag in (("pinion", "p"), ("gear", "g")):
        radius = gear["module_mm"] * 1e-3 * gear[f"teeth_{end}"] / 2
        mass = b.get(f"mass_{end}_kg", 2 * gear[f"inertia_{end}_kgm2"] / radius**2)
        values[f"M_{tag}"] = mass
        for direction, axis in (("loa", "y"), ("oloa", "x")):
            k = 1e6 * b.get(f"{end}_{direction}_stiffness_MN_per_m", b.get(f"{end}_stiffness_MN_per_m"))
            values[f"k_{tag}{axis}"] = k
            values[f"c_{tag}{axis}"] = 2 * b["damping_ratio"] * math.sqrt(k * mass)
    return dv.Bearings(**values)


@lru_cache(maxsize=None)
def built(combo: Combo, per_pair: bool = False):
    """``(model, parameters, rng)`` for a combination (deterministic; cached)."""
    rng = np.random.default_rng(zlib.crc32((combo.id + ("-per-pair" if per_pair else "")).encode()))
    while True:
        k1 = rng.uniform(200.0, 450.0) if per_pair else None
        data = config_dict(combo, rng, k_pair_MN_per_m=k1)
        try:
            cfg = parse_config(data)
            model = build_model(cfg)
        except ConfigError:  # a contact ratio this tooth pair cannot reach: draw again
            continue
        pp = dv.PerPair(k_pair=lambda xi, k=k1 * 1e6: np.full_like(xi, k)) if per_pair else None
        bearings = derivation_bearings(data) if combo.bearings else None
        return model, dv.parameters(cfg, bearings=bearings, per_pair=pp), rng


# ----------------------------------------------------------------------------------- states

#: contact states: "drive" (drive flank loaded, F_mesh > 0), "tension" (F_mesh < 0: bilateral
#: contact pulled, or a drive flank unloading faster than it compresses), "deadzone" (|x| < b),
#: "back" (x < -b, the back flank in contact)
REGIMES_LINEAR = ("drive", "tension")
REGIMES_BACKLASH = ("drive", "tension", "deadzone", "back")


def phases(p: dv.Parameters, rng, n: int, pitch_margin: float = 1e-6) -> np.ndarray:
    """Random mesh phases at least 1e-6 from the breakpoints (the stiffness jumps, pair exit and
    the pitch crossings: LTI's d_st' has a Dirac part there, Coulomb's sgn jumps), and at least
    `pitch_margin` from the pitch crossings. Near them ``V_s = xi_p Omega_p - xi_g Omega_g`` is a
    difference of nearly equal terms: at a phase distance ``d`` it keeps ~``eps / d`` of relative
    rounding, which a smooth law passes on to ``mu``; the OLOA rows of a model on bearings carry the
    friction force alone (no mesh force to dilute it), so there ``d = 1e-6`` would compare the two
    routes' rounding of ``V_s`` (~1e-12 seen at ``d ~ 1e-4``), not their equations."""
    s = rng.uniform(0.0, 1.0, 8 * n)
    g = p.geometry
    tb = (g.xP - g.xA) / g.pb
    far = np.min(np.abs(s[:, None] - p.breakpoints()[None]), axis=1) > 1e-6
    far &= np.min(np.abs(s[:, None] - np.array([tb, tb - 1.0])[None]), axis=1) > pitch_margin
    return s[far][:n]


def make_state(p: dv.Parameters, s, omega, regime: str, u, translations=None):
    """A physical state from uniform variates ``u`` (shape ``(5, n)``) in a contact regime.

    ``x = delta - eps`` and ``v = delta' - eps'`` are placed in the regime (with the derivation's
    own ``eps``, ``k`` and ``c``); the rigid-mode displacement and velocity are free. The centre
    translations are zero unless `translations` (shape ``(8, n)``: y_p, x_p, y_g, x_g [m] and their
    velocities [m/s]) is given; the rotations then absorb ``y_p - y_g`` so that ``x`` stays put."""
    g = p.geometry
    orders = np.arange(1, len(p.ste_amplitude) + 1)[:, None]
    amp, ph = np.asarray(p.ste_amplitude)[:, None], np.asarray(p.ste_phase)[:, None]
    eps = np.sum(amp * np.cos(2 * np.pi * orders * s + ph), axis=0)
    deps = -g.teeth_pinion * omega * np.sum(orders * amp * np.sin(2 * np.pi * orders * s + ph), axis=0)
    count = np.sum((g.xA + g.pb * (s[None] + np.arange(dv.PAIRS)[:, None])) <= g.xE, axis=0)
    k = np.where(count == 2, p.k_max, p.k_min)
    c = p.c * k / p.k_mean if p.damping_model == "proportional" else p.c + 0 * k
    b = p.backlash / 2
    static = p.normal_load / k
    if regime == "drive":
        x = b + static * (0.2 + 2.8 * u[0])
        v = np.minimum(0.9 * k * (x - b) / c, 2.0) * (2 * u[1] - 1)
    elif regime == "tension" and b > 0:
        x = b + static * 0.05 * u[0]
        v = -(k * (x - b) / c) * (1.2 + 1.8 * u[1]) - 0.3 * u[1]
    elif regime == "tension":
        x = -static * (0.1 + 1.9 * u[0])
        v = np.minimum(0.5, 0.9 * k * np.abs(x) / c) * (2 * u[1] - 1)
    elif regime == "deadzone":
        x = 0.95 * b * (2 * u[0] - 1)
        v = 2 * u[1] - 1
    elif regime == "back":
        x = -b - static * (0.05 + 1.95 * u[0])
        v = 2 * u[1] - 1
    else:
        raise ValueError(regime)
    delta, ddelta = eps + x, deps + v
    state = {name: 0.0 * s for name in dv.COORDINATES + tuple("d" + n for n in dv.COORDINATES)}
    if translations is not None:
        state |= {name: translations[i] for i, name in enumerate(TRANSLATIONS + tuple("d" + n for n in TRANSLATIONS))}
    delta = delta - state["y_p"] + state["y_g"]
    ddelta = ddelta - state["dy_p"] + state["dy_g"]
    phi_g, dphi_g = 1e-4 * (2 * u[2] - 1) / g.Rbg, (2 * u[3] - 1) / g.Rbg
    state |= dict(phi_p=(delta + g.Rbg * phi_g) / g.Rbp, phi_g=phi_g, dphi_p=(ddelta + g.Rbg * dphi_g) / g.Rbp,
                  dphi_g=dphi_g, windup=dv.static_windup(p, omega), reaction=p.normal_load * (0.8 + 0.4 * u[4]))
    return state


def draw(p: dv.Parameters, rng, regime: str, n: int = 24, moving: bool = False):
    """``(s, omega, state)`` batches at two random speeds (log-uniform in 200-20000 rpm); the centres
    `moving` (models on bearings) or at rest."""
    for rpm in 10 ** rng.uniform(math.log10(200.0), math.log10(20000.0), 2):
        omega = rpm * math.pi / 30
        s = phases(p, rng, n, pitch_margin=1e-2 if moving else 1e-6)
        centres = None
        if moving:  # centre displacements of ~1 um and velocities of ~0.1 m/s
            centres = np.concatenate([rng.normal(0, 1e-6, (4, s.size)), rng.normal(0, 0.1, (4, s.size))])
        yield s, omega, make_state(p, s, omega, regime, rng.uniform(0.0, 1.0, (5, s.size)), centres)


def agree(worst, what="relative error"):
    """Fail (without a traceback: hundreds of expected failures) unless within `RTOL`."""
    if not worst <= RTOL:
        pytest.fail(f"{what} {worst:.3e} > {RTOL:g}", pytrace=False)


def compare(model, p, s, omega, state):
    """Largest ``|model - derivation| / scale`` over the accelerations the model provides."""
    mine = dv.evaluate(p, s, omega, state)
    theirs, _ = model_view(model, p, s, omega, state)
    worst = 0.0
    for name, acc in theirs.items():
        scale = mine["scale"][name]
        assert np.all(scale > 0) and np.all(np.isfinite(acc))
        worst = max(worst, float(np.max(np.abs(acc - mine["acc"][name]) / scale)))
    return worst, mine


# --------------------------------------------------------------------------------- the tests


@pytest.mark.parametrize("combo", COMBOS, ids=lambda c: c.id)
def test_equations_of_motion_drive_flank(combo):
    """Every option combination, the drive flank loaded: the model's accelerations are the
    derivation's to 1e-12 of the terms' magnitude (random phases, speeds, DTE, velocities)."""
    model, p, _ = built(combo)
    rng = np.random.default_rng(zlib.crc32(combo.id.encode()) + 1)
    friction_seen = False
    for s, omega, state in draw(p, rng, "drive", moving=combo.bearings):
        worst, mine = compare(model, p, s, omega, state)
        assert np.all(mine["x"] > p.backlash / 2)
        if combo.coupling != "LTI":
            assert np.all(mine["F_mesh"] > 0)
        agree(worst)
        friction_seen |= bool(np.any(mine["mu"] * mine["normal"] != 0))
    assert friction_seen == (combo.law != "none")  # the friction terms were exercised


LOSS_CASES = [
    pytest.param(combo, regime, id=f"{combo.id}-{regime}")
    for combo in COMBOS
    for regime in (REGIMES_BACKLASH if combo.backlash else REGIMES_LINEAR)[1:]
]


@pytest.mark.parametrize("combo, regime", LOSS_CASES)
def test_equations_of_motion_large_vibration(combo, regime):
    """Large vibration: the teeth separate (dead zone), touch the back flank, or the
    formulation-B mesh force turns negative. The friction normal load follows MODEL.md §11."""
    model, p, _ = built(combo)
    rng = np.random.default_rng(zlib.crc32((combo.id + regime).encode()))
    for s, omega, state in draw(p, rng, regime, moving=combo.bearings):
        mine = dv.evaluate(p, s, omega, state)
        b = p.backlash / 2
        assert {"tension": True, "deadzone": np.all(np.abs(mine["x"]) < b),
                "back": np.all(mine["x"] < -b)}[regime]
        if regime == "tension" and combo.coupling != "LTI":
            assert np.all(mine["F_mesh"] < 0)
        worst, _ = compare(model, p, s, omega, state)
        agree(worst)


POWER_CASES = [
    pytest.param(coupling, formulation, backlash, law,
                 id=f"{coupling}-{formulation}-{'backlash' if backlash else 'linear'}-{law}")
    for coupling in ("LTI", "LTV", "NLTV")
    for formulation in (("A",) if coupling == "LTI" else ("A", "B"))
    for backlash in ((False,) if coupling == "LTI" else (False, True))
    for law in LAWS
]


@pytest.mark.parametrize("coupling, formulation, backlash, law", POWER_CASES)
@settings(max_examples=30, derandomize=True, deadline=None, database=None,
          phases=(Phase.explicit, Phase.generate))  # a counterexample need not be shrunk
@given(pick=st.integers(0, 1000), regime_pick=st.integers(0, 3), s=st.floats(0.0, 1.0, exclude_max=True),
       rpm=st.floats(50.0, 25000.0), u=st.lists(st.floats(0.0, 1.0), min_size=5, max_size=5))
def test_friction_power_is_never_positive_on_the_model(coupling, formulation, backlash, law, pick, regime_pick,
                                                       s, rpm, u):
    """MODEL.md §11 on the model itself: the friction power ``-sum_j mu_j N_j V_s,j`` (with the
    model's per-pair values) is never positive, for random states including separation, back
    flank contact, negative formulation-B mesh force and, on bearings, moving centres."""
    boundaries = ("spring", "reaction") if coupling == "NLTV" else ("torques", "spring", "reaction")
    combo = Combo(coupling, formulation, boundaries[pick % len(boundaries)], backlash, law,
                  ("constant", "proportional")[pick % 2], bool(pick % 3), bool((pick // 2) % 2))
    model, p, _ = built(combo)
    regimes = REGIMES_BACKLASH if backlash else REGIMES_LINEAR
    omega = rpm * math.pi / 30
    s = np.array([s])
    centres = None
    if combo.bearings:  # the centres' OLOA velocities enter V_s (MODEL.md §10): up to +-1 m/s
        centres = np.array([[1e-6 * (2 * u[0] - 1)], [0.0], [0.0], [-1e-6 * u[1]], [0.3 * (2 * u[2] - 1)],
                            [2 * u[3] - 1], [0.2 * u[4]], [1 - 2 * u[1]]])
    state = make_state(p, s, omega, regimes[regime_pick % len(regimes)], np.asarray(u)[:, None], centres)
    _, pair = model_view(model, p, s, omega, state)
    power = -np.sum(pair["mu"] * pair["normal"] * pair["vs"], axis=0)
    if not power[0] <= 0.0:
        pytest.fail(f"friction power {power[0]:.6g} W > 0", pytrace=False)


PER_PAIR_CASES = [
    Combo(coupling, formulation, boundary, backlash, law, "proportional", ste)
    for coupling in ("LTV", "NLTV")
    for formulation in ("A", "B")
    for boundary in (("spring", "reaction") if coupling == "NLTV" else ("torques", "spring", "reaction"))
    for backlash in (False, True)
    for law in LAWS
    for ste in (False, True)
]


@pytest.mark.parametrize("combo", PER_PAIR_CASES, ids=lambda c: c.id)
def test_per_pair_contact_constant_stiffness_limit(combo):
    """MODEL.md §9's limit: per-pair contact with ``k_pair = k1`` and no relief is the rectangular
    model with ``k_max = 2 k1``, ``k_min = k1``, equal sharing and proportional damping (drive
    flank loaded). With backlash §9 closes the drive flank at ``delta - eps > 0`` where §4 closes
    it at ``delta - eps > b``: the per-pair state is the rectangular one shifted by ``b``."""
    model, p, _ = built(combo, per_pair=True)
    rectangular = replace(p, per_pair=None)  # the same numbers, k(t) = k1 times the pairs in contact
    assert p.k_mean == pytest.approx(p.k_max * (p.geometry.gamma - 1) + p.k_min * (2 - p.geometry.gamma), rel=1e-13)
    rng = np.random.default_rng(zlib.crc32(combo.id.encode()) + 7)
    shift = p.backlash / 2 / p.geometry.Rbp
    for s, omega, state in draw(rectangular, rng, "drive"):
        pair_state = dict(state, phi_p=state["phi_p"] - shift)
        mine = dv.evaluate(p, s, omega, pair_state)
        assert np.all(mine["gap"][mine["sigma"] > 0] > 0)
        if combo.formulation == "B":
            assert np.all(mine["pair_force"][mine["sigma"] > 0] > 0)
        theirs, _ = model_view(model, p, s, omega, state)
        for name, acc in theirs.items():
            agree(float(np.max(np.abs(acc - mine["acc"][name]) / mine["scale"][name])), f"{name}: relative error")


# ------------------------------------------------------------------- the derivation itself


def test_kinematics_is_involute_action_and_model_md_section_10():
    """The compression rate does not depend on the contact position and has no nominal part
    (``Omega_p R_bp = Omega_g R_bg``); ``delta`` and ``V_s`` are MODEL.md §10's."""
    kin = dv.kinematics()
    S, (phi_p, phi_g, y_p, _, y_g, _), (dphi_p, dphi_g, _, dx_p, _, dx_g) = dv.S, dv.Q_SYM, dv.V_SYM
    m, zg, phi = sp.symbols("m Z_g phi", positive=True)
    gears = {S["R_bp"]: m * S["Z_p"] * sp.cos(phi) / 2, S["R_bg"]: m * zg * sp.cos(phi) / 2,
             S["W_g"]: S["W_p"] * S["Z_p"] / zg}
    for j in range(dv.PAIRS):
        nominal = kin.compression_rate[j].subs({v: 0 for v in dv.V_SYM})
        assert sp.simplify(nominal.subs(gears)) == 0
        assert sp.expand(kin.compression_rate[j] - nominal - kin.delta_rate) == 0
        vs = kin.xi_p[j] * (S["W_p"] + dphi_p) - kin.xi_g[j] * (S["W_g"] + dphi_g) + (dx_p - dx_g)
        assert sp.expand(kin.sliding[j] - vs) == 0
        vr = kin.xi_p[j] * (S["W_p"] + dphi_p) + kin.xi_g[j] * (S["W_g"] + dphi_g)
        assert sp.expand(kin.rolling[j] - vr) == 0
    assert all(c.free_symbols <= {S["R_bp"], S["R_bg"]} for c in kin.delta_coefficients)
    assert sp.expand(kin.delta - (S["R_bp"] * phi_p - S["R_bg"] * phi_g + y_p - y_g)) == 0
    # the frame: |O_g - O_p| = C with L = C sin(phi), R_bp + R_bg = C cos(phi)
    c = sp.Symbol("C", positive=True)
    centre = (S["R_bp"] + S["R_bg"]) * kin.n + S["L"] * kin.e1
    frame = {S["L"]: c * sp.sin(phi), S["R_bg"]: c * sp.cos(phi) - S["R_bp"]}
    assert sp.simplify(centre.dot(centre).subs(frame) - c**2) == 0


def test_derived_equations_are_model_md_section_10():
    """The equations from Lagrange and virtual work are MODEL.md §4/§10's, term by term."""
    eq = dv.equations("linear")
    S, (_, phi_g, y_p, x_p, y_g, x_g), (_, dphi_g, dy_p, dx_p, dy_g, dx_g) = dv.S, dv.Q_SYM, dv.V_SYM
    kin = dv.kinematics()
    x = kin.delta - kin.eps
    f_mesh = S["k"] * x + S["c"] * (kin.delta_rate - sp.diff(kin.eps, dv.t))
    t_fp = -sum(mu * n * xi for mu, n, xi in zip(dv.MU, dv.NORMAL, kin.xi_p))
    t_fg = sum(mu * n * xi for mu, n, xi in zip(dv.MU, dv.NORMAL, kin.xi_g))
    f_fp = [-mu * n for mu, n in zip(dv.MU, dv.NORMAL)]
    assert sp.expand(t_fp - sum(xi * f for xi, f in zip(kin.xi_p, f_fp))) == 0  # T_fp = sum xi_p F_fp,j
    theta_g = S["theta_w"] + phi_g
    written = [
        S["T_p"] - S["R_bp"] * f_mesh + t_fp,
        -S["T_g"] + S["R_bg"] * f_mesh + t_fg - S["k_b"] * theta_g - S["c_b"] * dphi_g,
        -f_mesh - S["c_py"] * dy_p - S["k_py"] * y_p,
        sum(f_fp) - S["c_px"] * dx_p - S["k_px"] * x_p,
        f_mesh - S["c_gy"] * dy_g - S["k_gy"] * y_g,
        -sum(f_fp) - S["c_gx"] * dx_g - S["k_gx"] * x_g,
    ]
    for derived, spec in zip(eq.force, written):
        assert sp.expand(derived - spec) == 0
    assert eq.mass == sp.diag(S["J_p"], S["J_g"], S["M_p"], S["M_p"], S["M_g"], S["M_g"])


def test_friction_virtual_work_dissipates():
    """The power of the contact-point friction forces along the total motion is
    ``-sum_j mu_j N_j V_s,j``: with ``mu_j`` signed like ``V_s,j`` and ``N_j >= 0`` it is <= 0."""
    eq = dv.equations("linear")
    kin = dv.kinematics()
    zero = {s: 0 for s in dv.MU}
    friction = [sp.expand(f - f.subs(zero)) for f in eq.force]
    speeds = [dv.S["W_p"] + dv.V_SYM[0], dv.S["W_g"] + dv.V_SYM[1], *dv.V_SYM[2:]]
    power = sum(f * v for f, v in zip(friction, speeds))
    assert sp.expand(power + sum(mu * n * vs for mu, n, vs in zip(dv.MU, dv.NORMAL, kin.sliding))) == 0


@pytest.mark.parametrize("combo", [Combo("NLTV", "B", "spring", True, "arctan", "proportional", True),
                                   Combo("NLTV", "A", "reaction", False, "kelley-lemanski", "constant", True),
                                   Combo("LTV", "B", "torques", False, "coulomb", "constant", False)],
                         ids=lambda c: c.id)
def test_derivation_with_moving_bearings_is_model_md_section_10(combo):
    """The derivation's numbers with the centres moving (what the multi-DOF model will be checked
    against): section 10's equations written out by hand, V_s with ``x_p' - x_g'``, and ``delta''``."""
    _, p, _ = built(combo)
    rng = np.random.default_rng(11)
    g, br = p.geometry, p.bearings
    s = phases(p, rng, 64)
    omega = 4000 * math.pi / 30
    moving = np.concatenate([rng.normal(0, 1e-6, (4, s.size)), rng.normal(0, 0.3, (4, s.size))])
    state = make_state(p, s, omega, "drive", rng.uniform(0, 1, (5, s.size)), moving)
    out = dv.evaluate(p, s, omega, state)
    acc, f = out["acc"], out["F_mesh"]
    assert np.all(out["x"] > p.backlash / 2) and np.all(f > 0)  # the rotations absorbed y_p - y_g
    wp, wg = p.speeds(omega)
    xi_p = g.xA + g.pb * (s[None] + np.arange(dv.PAIRS)[:, None])
    xi_g = g.L - xi_p
    vs = xi_p * (wp + state["dphi_p"]) - xi_g * (wg + state["dphi_g"]) + state["dx_p"] - state["dx_g"]
    np.testing.assert_allclose(out["vs_instantaneous"], vs, rtol=1e-12, atol=1e-12)
    friction = np.sum(out["mu"] * out["normal"], 0)  # cancels in double contact across the pitch point
    assert np.any(np.abs(friction) > 0.05 * p.normal_load * p.mu0)
    t_fp, t_fg = -np.sum(out["mu"] * out["normal"] * xi_p, 0), np.sum(out["mu"] * out["normal"] * xi_g, 0)
    t_g = p.output_torque(state["reaction"])
    written = {
        "phi_p": (p.torque - g.Rbp * f + t_fp) / p.J_p,
        "phi_g": (-t_g + g.Rbg * f + t_fg - p.k_b * (state["windup"] + state["phi_g"]) - p.c_b * state["dphi_g"]) / p.J_g,
        "y_p": (-f - br.c_py * state["dy_p"] - br.k_py * state["y_p"]) / br.M_p,
        "x_p": (-friction - br.c_px * state["dx_p"] - br.k_px * state["x_p"]) / br.M_p,
        "y_g": (f - br.c_gy * state["dy_g"] - br.k_gy * state["y_g"]) / br.M_g,
        "x_g": (friction - br.c_gx * state["dx_g"] - br.k_gx * state["x_g"]) / br.M_g,
    }
    for name, value in written.items():
        np.testing.assert_allclose(acc[name], value, rtol=0, atol=RTOL * np.max(out["scale"][name]))
    full = g.Rbp * acc["phi_p"] - g.Rbg * acc["phi_g"] + acc["y_p"] - acc["y_g"]
    np.testing.assert_allclose(acc["delta"], full, rtol=0, atol=RTOL * np.max(out["scale"]["delta"]))


def test_dead_zone_mesh_force_is_model_md_section_4():
    """``F_mesh = k g(delta - eps) + c (delta' - eps')`` with the dead zone of half-width b."""
    p = built(Combo("LTV", "A", "spring", True, "none", "constant", True))[1]
    rng = np.random.default_rng(3)
    s, omega = rng.uniform(0, 1, 400), 900.0
    b = p.backlash / 2
    state = {name: 0.0 * s for name in dv.COORDINATES + tuple("d" + n for n in dv.COORDINATES)}
    state |= dict(phi_p=rng.uniform(-4 * b, 4 * b, s.size) / p.geometry.Rbp, dphi_p=rng.normal(0, 30, s.size))
    out = dv.evaluate(p, s, omega, state)
    x = out["x"]
    g = np.where(x > b, x - b, np.where(x < -b, x + b, 0.0))
    rate = p.geometry.Rbp * state["dphi_p"] - out["deps"]
    np.testing.assert_allclose(out["F_mesh"], out["k"] * g + p.c * rate, rtol=1e-12, atol=1e-9)
    assert np.any(np.abs(x) < b) and np.any(x > b) and np.any(x < -b)


def test_relief_rate_is_the_time_derivative_of_the_relief():
    """Per-pair extension: the relief's rate (sympy's chain rule through ``xi(t)``) against a
    central difference of the relief itself."""
    combo = Combo("LTV", "B", "spring", False, "none", "proportional", False)
    p0 = built(combo, per_pair=True)[1]
    g = p0.geometry
    p = replace(p0, per_pair=dv.PerPair(
        k_pair=lambda xi: 3e8 + 1e12 * (xi - g.xA) * (g.xE - xi), ca_p=12e-6, xs_p=g.xA + 0.7 * (g.xE - g.xA),
        ca_g=9e-6, xs_g=g.xA + 0.25 * (g.xE - g.xA)))
    s, omega = np.random.default_rng(5).uniform(0.01, 0.99, 200), 1500.0
    state = {name: 0.0 * s for name in dv.COORDINATES + tuple("d" + n for n in dv.COORDINATES)}
    state["phi_p"] = 3e-5 / g.Rbp + 0 * s
    h = 1e-7
    out, up, down = (dv.evaluate(p, s + ds, omega, state) for ds in (0.0, h, -h))
    rate = (up["relief"] - down["relief"]) / (2 * h * p.mesh_period(omega))
    smooth = np.abs(up["relief_rate"] - down["relief_rate"]) == 0  # not across a relief start
    assert np.any(out["relief"] > 0) and np.sum(smooth) > 100
    np.testing.assert_allclose(out["relief_rate"][smooth], rate[smooth], rtol=1e-6, atol=1e-9)


def test_geometry_and_mesh_constants_from_model_md():
    """The derivation's geometry from module, teeth, pressure angle and contact ratio against the
    model's fields, and the reference pair's numbers quoted in MODEL.md §1."""
    cfg = load_config(EXAMPLE)
    p, model = dv.parameters(cfg), build_model(cfg)
    g = p.geometry
    assert g.addendum == pytest.approx(0.858, abs=5e-4)
    assert p.m_e == pytest.approx(0.4615, abs=5e-4)
    assert p.k_min == pytest.approx(451.9e6, rel=2e-4)
    assert (g.xP - g.xA) / g.pb == pytest.approx(0.726, abs=5e-4)
    for combo in COMBOS[::17]:
        model, p, _ = built(combo)
        g = p.geometry
        pairs = [(g.Rbp, model.base_radius_pinion_m), (g.Rbg, model.base_radius_gear_m), (g.L, model.line_of_action_m),
                 (g.xA, model.contact_start_m), (g.pb, model.base_pitch_m), (g.gamma, model.contact_ratio),
                 (p.k_min, model.k_min_N_per_m), (p.k_mean, model.k_mean_N_per_m), (p.m_e, model.mass_equivalent_kg)]
        for mine, theirs in pairs:
            assert float(theirs) == pytest.approx(mine, rel=1e-12)


def test_benedict_kelley_unit_conversion():
    """The US-customary law on a worked example, and the SI evaluation of the converted inputs."""
    mu = dv.benedict_kelley_us(1000.0, 10.0, 100.0, 400.0, 20.0)  # lb/in, cP, in/s, in/s, uin
    assert mu == pytest.approx(0.0127 * 50 / 30 * math.log10(3.17e8 * 1000 / (10 * 100 * 400**2)), rel=1e-15)
    assert mu == pytest.approx(0.06979, abs=1e-5)
    si = dv.kelley_lemanski_magnitude(1000 * 4.4482216152605 / 0.0254, 0.010, 100 * 0.0254, 400 * 0.0254,
                                      20 * 0.0254)
    assert float(si) == pytest.approx(mu, rel=1e-13)
    # the limits: no load -> 0, no sliding -> the cap, full film (argument < 1) -> 0
    assert dv.kelley_lemanski_magnitude(0.0, 0.01, 1.0, 10.0, 0.5) == 0.0
    assert dv.kelley_lemanski_magnitude(2e5, 0.01, 0.0, 10.0, 0.5) == dv.KELLEY_MU_CAP
    assert dv.kelley_lemanski_magnitude(1.0, 1.0, 50.0, 50.0, 0.5) == 0.0


@pytest.mark.parametrize("law", ("none", "coulomb", "arctan"))
@pytest.mark.parametrize("coupling, formulation", [("LTI", "A"), ("LTV", "A"), ("LTV", "B"), ("NLTV", "B")])
def test_static_windup(law, coupling, formulation):
    """The soft spring's static wind-up: the derivation's mean of the pinion and gear equations in
    the quasi-static state (adaptive quadrature) against ``model.static_windup`` (closed form for
    these laws). Kelley-Lemanski is left out: the model integrates it with a rule that does not
    place the law's interior kinks (cap and full-film onsets), so it agrees only to ~1e-7."""
    combo = Combo(coupling, formulation, "spring", False, law, "constant", True)
    model, p, _ = built(combo)
    for rpm in (150.0, 3000.0, 17000.0):
        omega = rpm * math.pi / 30
        mine = dv.static_windup(p, omega, adaptive=True) * p.geometry.Rbg
        assert float(model.static_windup(omega)) == pytest.approx(mine, rel=1e-12)


@dataclass(frozen=True)
class _QuadraticPair:
    """``k_pair(u) = k_0 + c_2 u (l - u)``, ``u`` from the start of the path (a JAX-ready pair stiffness)."""

    k0: float
    c2: float
    length: float

    def stiffness(self, xi, xp=np):
        xi = xp.asarray(xi)
        return self.k0 + self.c2 * xi * (self.length - xi)


@pytest.mark.parametrize("combo", PER_PAIR_CASES, ids=lambda c: c.id)
def test_per_pair_contact_with_relief_is_the_derivation(combo):
    """The real per-pair model (:class:`~hbgear.gear.mesh.PairContactMesh`: a stiffness varying
    along the path, tip relief on both gears) against the derivation's §9 mesh, in every regime of
    the rectangular model's states (pairs open where their relief exceeds the deflection; dead
    zone and back flank with backlash). The model keeps §4's ``delta`` (the derivation measures it
    from the drive flank's contact): the derivation's state is the model's shifted by ``b``."""
    from hbgear.gear.contact.profile import FlankRelief, ProfileModification
    from hbgear.gear.mesh import PairContactMesh

    model, p, _ = built(combo, per_pair=True)
    g = p.geometry
    length = g.xE - g.xA
    stiffness = _QuadraticPair(2.2e8, 4e13 / length, length)
    xs_p, xs_g = g.xA + 0.7 * length, g.xA + 0.3 * length
    relief = ProfileModification(pinion=FlankRelief(tip_relief_m=30e-6, tip_length_m=g.xE - xs_p),
                                 gear=FlankRelief(tip_relief_m=25e-6, tip_length_m=xs_g - g.xA))
    pair_model = model.replace(mesh=PairContactMesh.build(stiffness, relief, model))
    pp = replace(p, per_pair=dv.PerPair(k_pair=lambda xi: stiffness.stiffness(xi - g.xA), ca_p=30e-6, xs_p=xs_p,
                                        ca_g=25e-6, xs_g=xs_g))
    assert float(pair_model.k_mean_N_per_m) == pytest.approx(pp.k_mean, rel=1e-12)
    rectangular = replace(p, per_pair=None)
    rng = np.random.default_rng(zlib.crc32(combo.id.encode()) + 11)
    shift = p.backlash / 2 / g.Rbp
    opened = 0
    # without backlash the model's back flank closes at x < 0 (zero backlash: the rectangular model's
    # teeth that never separate), the derivation's per-pair mesh has none there: drive-side states only
    for regime in (REGIMES_BACKLASH if combo.backlash else ("drive",)):
        for s, omega, state in draw(rectangular, rng, regime):
            mine = dv.evaluate(pp, s, omega, dict(state, phi_p=state["phi_p"] - shift))
            theirs, pair = model_view(pair_model, pp, s, omega, state)
            opened += int(np.sum((mine["gap"] <= 0) & (mine["sigma"] > 0)))
            for name, acc in theirs.items():
                agree(float(np.max(np.abs(acc - mine["acc"][name]) / mine["scale"][name])), f"{name}: relative error")
            inside = mine["sigma"] > 0
            for key in ("mu", "normal"):  # the loads of two static contact solves (library; the
                # derivation's sorted offsets) were seen to differ by up to 1.7e-12 of the largest
                scale = np.max(np.abs(mine[key])) + 1e-300
                worst = float(np.max(np.abs(np.where(inside, pair[key] - mine[key], 0.0))) / scale)
                if not worst <= 1e-11:
                    pytest.fail(f"{key}: relative error {worst:.3e} > 1e-11", pytrace=False)
    assert opened > 0  # some pair of the path open: the contact gate was exercised
