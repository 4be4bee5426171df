r"""A second, independent derivation of the gear pair's equations of motion (tests only).

Nothing here imports ``hbgear``: the geometry, the mesh-phase functions, the friction laws, the
normal-load rule and the equations themselves are derived again from ``docs/MODEL.md``
(sections 1-4, 9-11) and from energies and virtual work with sympy. The tests compare the
accelerations this derivation gives with those of ``GearPairModel.generalized_force``.

**Frame and sign conventions** (plane of the gears, ``z`` out of the plane, right-handed):

- pinion centre ``O_p`` at the origin; ``n`` the unit vector from ``O_p`` to the pinion's
  base-circle tangency point ``T1 = O_p + R_bp n``; ``e1 = z x n`` the line of action (LOA) from
  ``T1`` to ``T2 = T1 + L e1``; gear centre ``O_g = T2 + R_bg n``; ``e2 = -n`` the
  off-line-of-action (OLOA) axis (chosen so that ``T_fp = sum_j xi_p,j F_fp,j``, MODEL.md §10).
- the pinion turns about ``+z`` at ``Omega_p + phi_p'`` (its base circle at ``T1`` moves along
  ``+e1``); the gear turns about ``-z`` at ``Omega_g + phi_g'`` (its base circle at ``T2`` moves
  along ``+e1`` too: the crossed belt of an external mesh).
- centre translations ``y`` along ``e1`` (``y_p > 0`` closes the mesh) and ``x`` along ``e2``.
- contact point of pair ``j``: ``P_j = T1 + xi_p,j e1 = T2 - xi_g,j e1`` at its nominal position
  ``xi_p,j(t) = x_A + R_bp Omega_p (t + j T_m)`` (pair ``j`` entered ``j`` mesh periods before
  the current one; the vibration does not move the contact points: first order).

**Generalised coordinates** ``q = (phi_p, phi_g, y_p, x_p, y_g, x_g)``: the rotations are
vibratory deviations from the nominal rotation about a constant rigid wind-up ``theta_w``
(``theta_p = theta_w R_bg/R_bp + phi_p``, ``theta_g = theta_w + phi_g``; the mesh does not see
the wind-up, the soft output spring does), plus the centre translations (MODEL.md §10; the
2-DOF model of today is their rigid-bearing limit).

**Material-point velocities at** ``P_j`` (what every force below does work through)::

    v_p,j = (Omega_p + phi_p') z x rho_p,j + y_p' e1 + x_p' e2,   rho_p,j = R_bp n + xi_p,j e1
    v_g,j = -(Omega_g + phi_g') z x rho_g,j + y_g' e1 + x_g' e2,  rho_g,j = -R_bg n - xi_g,j e1

The compression rate is ``(v_p,j - v_g,j) . e1`` (the flank normal is ``e1``); it does not depend
on ``xi`` (involute action) and its nominal part vanishes (``Omega_p R_bp = Omega_g R_bg``), so the
compression ``delta`` is the linear form with those coefficients. The sliding velocity is
``V_s,j = (v_p,j - v_g,j) . e2``; the rolling (sum) velocity is the sum of both surfaces'
``e2``-speeds relative to their own centres (MODEL.md §3's ``V_r``; §10 is silent on it).

**Lagrangian and Rayleigh function**::

    T = 1/2 J_p (Omega_p + phi_p')^2 + 1/2 J_g (Omega_g + phi_g')^2
        + 1/2 M_p (y_p'^2 + x_p'^2) + 1/2 M_g (y_g'^2 + x_g'^2)
    V = V_mesh + 1/2 k_b (theta_w + phi_g)^2 + 1/2 sum k_(bearing) (translation)^2
    R = R_mesh + 1/2 c_b phi_g'^2 + 1/2 sum c_(bearing) (translation')^2

with the mesh terms (``x = delta - eps(t)``, ``eps`` the unloaded STE as an explicit function of
time, so that ``eps'`` comes from sympy's derivative):

- ``"linear"``: ``V_mesh = 1/2 k(t) x^2``, ``R_mesh = 1/2 c(t) (delta' - eps')^2``;
- ``"dead-zone"`` (backlash ``2b``): ``V_mesh = 1/2 k(t) G(x)`` with ``G = (x-b)^2`` for
  ``x > b``, ``(x+b)^2`` for ``x < -b``, 0 between; ``R_mesh`` as above (MODEL.md §4 keeps the
  damper in the dead zone);
- ``"lti"``: ``V_mesh = 1/2 k_mean (delta - d_st)^2``, ``R_mesh = 1/2 c (delta' - d_st')^2``,
  ``d_st = eps + N/k(t) - N <1/k>`` with ``k(t)`` piecewise constant (so ``d_st' = eps'`` away
  from the jumps);
- ``"per-pair"`` (MODEL.md §9): ``V_mesh = sum_j 1/2 k_j max(x_j, 0)^2``, ``x_j = x - e_j(t)``,
  ``R_mesh = sum_j [x_j > 0] 1/2 c_j (x_j')^2``; with backlash (``"per-pair-backlash"``) the back
  flank of pair ``j`` closes at ``x < -2b`` in the same way (mirror geometry, no back relief).

``k(t)``, ``c(t)``, ``k_j`` enter as the values at the instant (the generalised forces are
partial derivatives at fixed time). **Virtual work** of the non-conservative forces::

    dW = T_p d(theta_p) - T_g d(theta_g) + sum_j (F_p,j . dr_p(P_j) + F_g,j . dr_g(P_j))
    F_p,j = -mu_j N_j e2  (friction on the pinion tooth),   F_g,j = +mu_j N_j e2

with ``dr(P_j) = (d v(P_j)/d q') dq`` from the velocities above. ``mu_j`` (signed like the
sliding velocity) and ``N_j >= 0`` are constitutive inputs (MODEL.md §3, §11), evaluated by the
numeric part of this module. The equations ``M q'' = Q`` follow from Lagrange's equations with
``d/dt dT/dq'`` expanded by the chain rule; the mesh force is the LOA force on the gear centre,
``F_mesh = -dV_mesh/dy_g - dR_mesh/dy_g'``.

Everything numeric (base radii, line of action, start of active contact, base pitch, contact
positions, load shares, ``k(t)``, ``k_mean``, ``m_e``, ``c``, the soft spring, the static
wind-up, the friction laws including the NLTV regularisation and the Benedict-Kelley law in its
US-customary form) is computed here from the configuration's numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Callable

import numpy as np
import sympy as sp
from scipy import integrate, optimize

COORDINATES = ("phi_p", "phi_g", "y_p", "x_p", "y_g", "x_g")
PAIRS = 2  # a contact ratio below 2: at most two pairs
STE_ORDERS = 3  # mesh orders of the unloaded STE the symbolic equations carry (unused = 0)
MESHES = ("linear", "dead-zone", "lti", "per-pair", "per-pair-backlash")

# ----------------------------------------------------------------------------------- symbols


def _s(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


t = _s("t")
Q_SYM = tuple(_s(n) for n in COORDINATES)
V_SYM = tuple(_s("d" + n) for n in COORDINATES)
A_SYM = tuple(_s("dd" + n) for n in COORDINATES)
S = {
    n: _s(n)
    for n in (
        "J_p J_g M_p M_g R_bp R_bg L x_A x_E Z_p W_p W_g T_p T_g theta_w k_b c_b "
        "k_py c_py k_px c_px k_gy c_gy k_gx c_gx k c b k_mean N_load C_mean "
        "ca_p xs_p ca_g xs_g"
    ).split()
}
STE_A = tuple(_s(f"A_{n}") for n in range(1, STE_ORDERS + 1))
STE_PH = tuple(_s(f"ph_{n}") for n in range(1, STE_ORDERS + 1))
MU = tuple(_s(f"mu_{j}") for j in range(PAIRS))
NORMAL = tuple(_s(f"N_{j}") for j in range(PAIRS))
K_PAIR = tuple(_s(f"k_{j}") for j in range(PAIRS))
C_PAIR = tuple(_s(f"c_{j}") for j in range(PAIRS))
RELIEF = tuple(_s(f"E_{j}") for j in range(PAIRS))
RELIEF_RATE = tuple(_s(f"dE_{j}") for j in range(PAIRS))


def _z_cross(v: sp.Matrix) -> sp.Matrix:
    return sp.Matrix([-v[1], v[0]])


def _positive_part(x):
    return sp.Piecewise((x, x > 0), (0, True))


def magnitude(expr) -> sp.Expr:
    """A bound on the size of the numbers an evaluation of `expr` adds up: ``|a + b| -> |a| + |b|``,
    ``|a b| -> |a| |b|``, functions and symbols by their absolute value, Piecewise per branch.

    The comparison tolerance is relative to it, so that cancellations (a wound-up soft spring
    against the input torque, ``k_mean (delta - d_st)``) do not make a relative tolerance
    meaningless, while each term still has to be right to that tolerance."""
    if isinstance(expr, sp.Add):
        return sp.Add(*[magnitude(a) for a in expr.args])
    if isinstance(expr, sp.Mul):
        return sp.Mul(*[magnitude(a) for a in expr.args])
    if isinstance(expr, sp.Pow) and expr.exp.is_Integer:
        return magnitude(expr.base) ** expr.exp
    if isinstance(expr, sp.Piecewise):
        return sp.Piecewise(*[(magnitude(e), c) for e, c in expr.args])
    return sp.Abs(expr)


@dataclass(frozen=True)
class Kinematics:
    """The symbolic kinematics of the contact points (shared by every mesh model)."""

    xi_p: tuple
    xi_g: tuple
    v_p: tuple  # material-point velocities at P_j, pinion
    v_g: tuple
    compression_rate: tuple  # (v_p,j - v_g,j) . e1, total (nominal part included)
    delta_coefficients: tuple  # d delta / d q_k
    delta: sp.Expr
    delta_rate: sp.Expr
    sliding: tuple  # V_s,j
    rolling: tuple  # V_r,j
    eps: sp.Expr
    e1: sp.Matrix
    e2: sp.Matrix
    n: sp.Matrix


@lru_cache(maxsize=None)
def kinematics() -> Kinematics:
    n = sp.Matrix([1, 0])
    e1 = _z_cross(n)
    e2 = -n
    tm = 2 * sp.pi / (S["Z_p"] * S["W_p"])
    xi_p = tuple(S["x_A"] + S["R_bp"] * S["W_p"] * (t + j * tm) for j in range(PAIRS))
    xi_g = tuple(S["L"] - x for x in xi_p)
    phi_p, phi_g, y_p, x_p, y_g, x_g = Q_SYM
    dphi_p, dphi_g, dy_p, dx_p, dy_g, dx_g = V_SYM
    centre_p = dy_p * e1 + dx_p * e2
    centre_g = dy_g * e1 + dx_g * e2
    v_p, v_g, rate, sliding, rolling = [], [], [], [], []
    for j in range(PAIRS):
        rho_p = S["R_bp"] * n + xi_p[j] * e1
        rho_g = -S["R_bg"] * n - xi_g[j] * e1
        vp = (S["W_p"] + dphi_p) * _z_cross(rho_p) + centre_p
        vg = -(S["W_g"] + dphi_g) * _z_cross(rho_g) + centre_g
        v_p.append(vp)
        v_g.append(vg)
        rate.append(sp.expand((vp - vg).dot(e1)))
        sliding.append(sp.expand((vp - vg).dot(e2)))
        rolling.append(sp.expand((vp - centre_p).dot(e2) + (vg - centre_g).dot(e2)))
    vibration_rate = sp.expand(rate[0] - rate[0].subs({v: 0 for v in V_SYM}))
    coefficients = tuple(sp.diff(vibration_rate, v) for v in V_SYM)
    delta = sum(c * q for c, q in zip(coefficients, Q_SYM))
    wm = S["Z_p"] * S["W_p"]
    eps = sum(a * sp.cos((i + 1) * wm * t + ph) for i, (a, ph) in enumerate(zip(STE_A, STE_PH)))
    return Kinematics(tuple(xi_p), xi_g, tuple(v_p), tuple(v_g), tuple(rate), coefficients, delta,
                      vibration_rate, tuple(sliding), tuple(rolling), eps, e1, e2, n)


def _relief(kin: Kinematics, j: int) -> sp.Expr:
    """Composite profile deviation ``e_j = e_p(xi_p,j) + e_g(xi_g,j)`` of pair ``j``: linear tip
    relief of depth ``ca_p`` on the pinion from ``xs_p`` to the end of contact ``x_E``, and of
    ``ca_g`` on the gear from ``xs_g`` back to the start of contact ``x_A`` (positions along the
    LOA from T1; positive = material removed)."""
    xi = kin.xi_p[j]
    tip_p = S["ca_p"] * _positive_part((xi - S["xs_p"]) / (S["x_E"] - S["xs_p"]))
    tip_g = S["ca_g"] * _positive_part((S["xs_g"] - xi) / (S["xs_g"] - S["x_A"]))
    return tip_p + tip_g


@dataclass(frozen=True)
class Equations:
    """Lambdified equations of one mesh model (see the module docstring)."""

    mesh: str
    mass: sp.Matrix
    force: tuple  # Q_k (symbolic)
    acceleration: tuple  # q_k'' (symbolic)
    functions: dict  # name -> (argument names, numpy function)

    def __call__(self, name: str, values: dict, shape) -> np.ndarray:
        names, fn = self.functions[name]
        out = fn(*[values[a] for a in names])
        return np.stack([o if np.shape(o) == shape else np.broadcast_to(np.asarray(o, dtype=float), shape)
                         for o in out])


def _lambdify(exprs) -> tuple:
    exprs = [sp.sympify(e) for e in exprs]
    free = sorted(set().union(*[e.free_symbols for e in exprs]), key=lambda s: s.name)
    return tuple(a.name for a in free), sp.lambdify(free, exprs, modules="numpy", cse=True)


@lru_cache(maxsize=None)
def equations(mesh: str) -> Equations:
    """Derive (once per mesh model) and lambdify the equations of motion."""
    if mesh not in MESHES:
        raise ValueError(mesh)
    kin = kinematics()
    x = kin.delta - kin.eps
    x_rate = kin.delta_rate - sp.diff(kin.eps, t)
    extra = {}
    if mesh == "linear":
        v_mesh = S["k"] / 2 * x**2
        r_mesh = S["c"] / 2 * x_rate**2
    elif mesh == "dead-zone":
        b = S["b"]
        v_mesh = S["k"] / 2 * sp.Piecewise(((x - b) ** 2, x > b), ((x + b) ** 2, x < -b), (0, True))
        r_mesh = S["c"] / 2 * x_rate**2
    elif mesh == "lti":
        d_st = kin.eps + S["N_load"] / S["k"] - S["N_load"] * S["C_mean"]
        v_mesh = S["k_mean"] / 2 * (kin.delta - d_st) ** 2
        r_mesh = S["c"] / 2 * (kin.delta_rate - sp.diff(d_st, t)) ** 2
    else:
        # e_j and e_j' enter the mechanics as the values at the instant (symbols E_j, dE_j);
        # their expressions in time (relief(), its sympy time derivative) are a second stage
        v_mesh = r_mesh = 0
        pair_gap, pair_force_parts = [], []
        for j in range(PAIRS):
            xj = x - RELIEF[j]
            xj_rate = x_rate - RELIEF_RATE[j]
            vj = K_PAIR[j] / 2 * sp.Piecewise((xj**2, xj > 0), (0, True))
            rj = C_PAIR[j] / 2 * sp.Piecewise((xj_rate**2, xj > 0), (0, True))
            if mesh == "per-pair-backlash":
                xb = x + 2 * S["b"]  # back flank: closes at x < -2b
                vj += K_PAIR[j] / 2 * sp.Piecewise((xb**2, xb < 0), (0, True))
                rj += C_PAIR[j] / 2 * sp.Piecewise((x_rate**2, xb < 0), (0, True))
            v_mesh += vj
            r_mesh += rj
            pair_gap.append(xj)
            pair_force_parts.append((vj, rj))
        extra["pair_gap"] = pair_gap
        extra["pair_parts"] = pair_force_parts

    # the rest of the potential, the dissipation and the virtual work
    phi_p, phi_g, y_p, x_p, y_g, x_g = Q_SYM
    dphi_p, dphi_g, dy_p, dx_p, dy_g, dx_g = V_SYM
    kinetic = (S["J_p"] / 2 * (S["W_p"] + dphi_p) ** 2 + S["J_g"] / 2 * (S["W_g"] + dphi_g) ** 2
               + S["M_p"] / 2 * (dy_p**2 + dx_p**2) + S["M_g"] / 2 * (dy_g**2 + dx_g**2))
    v_other = (S["k_b"] / 2 * (S["theta_w"] + phi_g) ** 2 + S["k_py"] / 2 * y_p**2
               + S["k_px"] / 2 * x_p**2 + S["k_gy"] / 2 * y_g**2 + S["k_gx"] / 2 * x_g**2)
    r_other = (S["c_b"] / 2 * dphi_g**2 + S["c_py"] / 2 * dy_p**2 + S["c_px"] / 2 * dx_p**2
               + S["c_gy"] / 2 * dy_g**2 + S["c_gx"] / 2 * dx_g**2)
    applied = [S["T_p"], -S["T_g"], 0, 0, 0, 0]  # dW = T_p d theta_p - T_g d theta_g
    friction = [0] * 6
    for j in range(PAIRS):
        f_p = -MU[j] * NORMAL[j] * kin.e2
        f_g = MU[j] * NORMAL[j] * kin.e2
        for k, v in enumerate(V_SYM):
            friction[k] += f_p.dot(sp.diff(kin.v_p[j], v)) + f_g.dot(sp.diff(kin.v_g[j], v))

    def generalised(v_pot, r_diss, q_k, v_k):
        return -sp.diff(v_pot, q_k) - sp.diff(r_diss, v_k)

    forces, magnitudes, lagrange = [], [], []
    for k in range(6):
        p_k = sp.diff(kinetic, V_SYM[k])
        inertial_rest = (sum(sp.diff(p_k, Q_SYM[j]) * V_SYM[j] for j in range(6)) + sp.diff(p_k, t)
                         - sp.diff(kinetic, Q_SYM[k]))
        parts = [generalised(v_mesh, r_mesh, Q_SYM[k], V_SYM[k]),
                 generalised(v_other, r_other, Q_SYM[k], V_SYM[k]),
                 sp.sympify(applied[k]), sp.expand(friction[k]), -inertial_rest]
        forces.append(sum(parts))
        magnitudes.append(sum(magnitude(p) for p in parts))
        lagrange.append(sum(sp.diff(p_k, V_SYM[j]) * A_SYM[j] for j in range(6)) - forces[-1])
    mass = sp.Matrix(lagrange).jacobian(A_SYM)
    assert all(sp.diff(m, s) == 0 for m in mass for s in Q_SYM + V_SYM + (t,)), "constant mass matrix"
    inverse = mass.inv()
    acceleration = inverse * sp.Matrix(forces)
    scale = inverse.applyfunc(sp.Abs) * sp.Matrix(magnitudes)
    # delta'' of the full motion, and of the rotations alone (the rigid-bearing limit, where the
    # translations are held: their accelerations are the bearings' reactions, not motion)
    acc_delta = [sum(c * a for c, a in zip(kin.delta_coefficients[:n], acceleration[:n])) for n in (6, 2)]
    scale_delta = [sum(sp.Abs(c) * a for c, a in zip(kin.delta_coefficients[:n], scale[:n])) for n in (6, 2)]

    mesh_force = generalised(v_mesh, r_mesh, y_g, dy_g)  # LOA force on the gear
    nominal = {v: 0 for v in V_SYM}
    kinematic_out = [kin.delta, kin.delta_rate, x, kin.eps, sp.diff(kin.eps, t), *kin.xi_p, *kin.xi_g,
                     *kin.sliding, *[v.subs(nominal) for v in kin.sliding],
                     *kin.rolling, *[v.subs(nominal) for v in kin.rolling], mesh_force]
    functions = {
        "positions": _lambdify([*kin.xi_p, *kin.xi_g]),
        "kinematics": _lambdify(kinematic_out),
        "accelerations": _lambdify([*acceleration, *acc_delta]),
        "scales": _lambdify([*scale, *scale_delta]),
    }
    if mesh.startswith("per-pair"):
        gaps = extra["pair_gap"]
        pair_forces = [generalised(vj, rj, y_g, dy_g) for vj, rj in extra["pair_parts"]]
        functions["pairs"] = _lambdify([*gaps, *pair_forces])
        reliefs = [_relief(kin, j) for j in range(PAIRS)]
        functions["relief"] = _lambdify([*reliefs, *[sp.diff(e, t) for e in reliefs]])
    return Equations(mesh, mass, tuple(forces), tuple(acceleration), functions)


# ------------------------------------------------------------------------- numeric parameters

# unit definitions for the Benedict-Kelley law (exact): 1 in = 0.0254 m, 1 lbf = 4.4482216152605 N
METRE_PER_INCH = 0.0254
NEWTON_PER_LBF = 4.4482216152605
PA_S_PER_CENTIPOISE = 1e-3
#: cap on |mu| of the Kelley-Lemanski law (docs/kelley_lemanski.md: boundary-lubrication level)
KELLEY_MU_CAP = 0.15


@lru_cache(maxsize=None)
def _soft_mode_inertia():
    """Inertia about the gear of the rigid-mesh rotation (``delta = 0``, rigid bearings): twice
    the kinetic energy of the vibration per unit ``phi_g'^2`` with ``phi_p`` following ``phi_g``."""
    kin = kinematics()
    delta = kin.delta.subs({q: 0 for q in Q_SYM[2:]})
    rigid = Q_SYM[0] - delta / sp.diff(delta, Q_SYM[0])  # phi_p(phi_g) with delta = 0 (delta is linear)
    rate = sp.diff(rigid, Q_SYM[1])
    inertia = S["J_p"] * rate**2 + S["J_g"]
    return sp.lambdify([S["J_p"], S["J_g"], S["R_bp"], S["R_bg"]], inertia)


@dataclass(frozen=True)
class Geometry:
    """MODEL.md §1 from teeth, module, pressure angle and the addendum coefficient."""

    teeth_pinion: int
    teeth_gear: int
    module: float
    pressure_angle: float
    addendum: float

    def __post_init__(self):
        m, zp, zg, phi, ha = self.module, self.teeth_pinion, self.teeth_gear, self.pressure_angle, self.addendum
        rp, rg = m * zp / 2, m * zg / 2
        values = dict(rp=rp, rg=rg, Rbp=rp * math.cos(phi), Rbg=rg * math.cos(phi), rap=rp + ha * m,
                      rag=rg + ha * m, C=rp + rg)
        values["L"] = values["C"] * math.sin(phi)
        values["pb"] = 2 * math.pi * values["Rbp"] / zp
        values["xA"] = values["L"] - math.sqrt(values["rag"] ** 2 - values["Rbg"] ** 2)
        values["xE"] = math.sqrt(values["rap"] ** 2 - values["Rbp"] ** 2)
        values["xP"] = values["Rbp"] * math.tan(phi)
        values["gamma"] = (values["xE"] - values["xA"]) / values["pb"]
        for key, value in values.items():
            object.__setattr__(self, key, value)

    @classmethod
    def with_contact_ratio(cls, zp, zg, module, phi, gamma):
        """The common addendum coefficient for a target contact ratio (Brent, to rounding)."""
        ha = optimize.brentq(lambda h: cls(zp, zg, module, phi, h).gamma - gamma, 1e-6, 2.0,
                             xtol=1e-16, rtol=4 * np.finfo(float).eps, maxiter=500)
        return cls(zp, zg, module, phi, ha)


@dataclass(frozen=True)
class Bearings:
    """Centre masses and bearing springs/dampers (MODEL.md §10); irrelevant while rigid."""

    M_p: float = 1.3
    M_g: float = 2.1
    k_py: float = 3e8
    c_py: float = 900.0
    k_px: float = 2e8
    c_px: float = 700.0
    k_gy: float = 4e8
    c_gy: float = 1100.0
    k_gx: float = 2.5e8
    c_gx: float = 800.0


@dataclass(frozen=True)
class PerPair:
    """Per-pair contact (MODEL.md §9): ``k_pair(xi_p)`` [N/m] and linear tip relief."""

    k_pair: Callable[[np.ndarray], np.ndarray]
    ca_p: float = 0.0  # pinion tip relief depth [m], from xs_p to x_E
    xs_p: float | None = None  # [m] along the LOA; default: the middle of the path
    ca_g: float = 0.0  # gear tip relief depth [m], from xs_g back to x_A
    xs_g: float | None = None


@dataclass(frozen=True)
class Parameters:
    """Every number the derivation needs, from the configuration (SI)."""

    geometry: Geometry
    J_p: float
    J_g: float
    k_max: float
    k_mean_config: float | None
    k_min_config: float | None
    zeta: float
    damping_model: str
    backlash: float  # total, 2b
    ste_amplitude: tuple
    ste_phase: tuple
    torque: float
    face_width: float
    coupling: str
    formulation: str
    boundary: str
    law: str
    mu0: float
    v0: float
    viscosity: float
    roughness_um: float
    v_reg: float
    spring_ratio: float
    spring_zeta: float
    bearings: Bearings = field(default_factory=Bearings)
    per_pair: PerPair | None = None

    # -- MODEL.md §1-§4 -------------------------------------------------------------------
    @property
    def k_min(self) -> float:
        if self.k_min_config is not None:
            return self.k_min_config
        g = self.geometry.gamma
        return (self.k_mean_config - self.k_max * (g - 1)) / (2 - g)

    @cached_property
    def k_mean(self) -> float:
        """Rectangular: ``k_max (Gamma-1) + k_min (2-Gamma)``; per pair: the mesh-period mean of
        ``sum_j k_pair(xi_j)`` over the pairs in the path of contact (§9)."""
        g = self.geometry
        if self.per_pair is None:
            return self.k_max * (g.gamma - 1) + self.k_min * (2 - g.gamma)

        def total(s):
            xi = g.xA + g.pb * (s + np.arange(PAIRS))
            inside = (xi >= g.xA) & (xi <= g.xE)
            return float(np.sum(np.where(inside, self.per_pair.k_pair(xi), 0.0)))

        pieces = [0.0, g.gamma - 1, 1.0]
        return sum(integrate.quad(total, a, b_, epsabs=0, epsrel=1e-13, limit=200)[0]
                   for a, b_ in zip(pieces[:-1], pieces[1:]))

    @property
    def normal_load(self) -> float:
        return self.torque / self.geometry.Rbp

    @property
    def m_e(self) -> float:
        g = self.geometry
        return 1.0 / (g.Rbp**2 / self.J_p + g.Rbg**2 / self.J_g)

    @property
    def c(self) -> float:
        return 2 * self.zeta * math.sqrt(self.k_mean * self.m_e)

    @property
    def mean_compliance(self) -> float:
        """``<1/k>`` over a mesh period: ``1/k_max`` for a fraction ``Gamma - 1``, else ``1/k_min``."""
        g = self.geometry.gamma
        return (g - 1) / self.k_max + (2 - g) / self.k_min

    @property
    def k_b(self) -> float:
        """Soft output spring ``k_b = k_mean R_bg^2 / ratio`` [N m/rad] (spring boundary only)."""
        return self.k_mean * self.geometry.Rbg**2 / self.spring_ratio if self.boundary == "spring" else 0.0

    @property
    def c_b(self) -> float:
        """Damper of the soft mode: damping ratio ``zeta_b`` of the rigid-mesh rotation on ``k_b``,
        whose inertia (about the gear) follows from the kinetic energy with ``delta = 0``."""
        if self.boundary != "spring":
            return 0.0
        g = self.geometry
        inertia = _soft_mode_inertia()(self.J_p, self.J_g, g.Rbp, g.Rbg)
        return 2 * self.spring_zeta * math.sqrt(self.k_b * inertia)

    def output_torque(self, reaction) -> np.ndarray | float:
        if self.boundary == "torques":
            return self.torque * self.geometry.Rbg / self.geometry.Rbp
        if self.boundary == "reaction":
            return self.geometry.Rbg * reaction
        return 0.0

    def speeds(self, omega_p):
        g = self.geometry
        return omega_p, omega_p * g.teeth_pinion / g.teeth_gear

    def mesh_period(self, omega_p):
        return 2 * math.pi / (self.geometry.teeth_pinion * omega_p)

    def breakpoints(self) -> np.ndarray:
        """Mesh phases where something jumps: entry, exit, pitch crossings (and 1)."""
        g = self.geometry
        tb = (g.xP - g.xA) / g.pb
        points = {0.0, g.gamma - 1, 1.0}
        points |= {tb - j for j in range(PAIRS) if 0 <= tb - j < 1 and tb < g.gamma}
        return np.array(sorted(points))


def parameters(cfg, bearings: Bearings | None = None, per_pair: PerPair | None = None) -> Parameters:
    """The numbers of a ``RunConfig`` (data only: every derived quantity is computed here)."""
    gear, mesh, fr, bd = cfg.gear, cfg.mesh, cfg.friction, cfg.boundary
    if gear.contact_ratio is not None:
        geometry = Geometry.with_contact_ratio(gear.teeth_pinion, gear.teeth_gear, gear.module_m,
                                               gear.pressure_angle_rad, gear.contact_ratio)
    else:
        geometry = Geometry(gear.teeth_pinion, gear.teeth_gear, gear.module_m, gear.pressure_angle_rad,
                            gear.addendum_coefficient)
    law = fr.law
    if law in ("coulomb", "arctan") and fr.mu0 == 0.0:
        law = "none"
    return Parameters(
        geometry=geometry, J_p=gear.inertia_pinion_kgm2, J_g=gear.inertia_gear_kgm2,
        k_max=mesh.k_max_N_per_m, k_mean_config=mesh.k_mean_N_per_m, k_min_config=mesh.k_min_N_per_m,
        zeta=mesh.damping_ratio, damping_model=mesh.damping_model, backlash=mesh.backlash_m,
        ste_amplitude=tuple(mesh.ste_amplitude_m), ste_phase=tuple(mesh.ste_phase_rad),
        torque=cfg.load.torque_pinion_Nm, face_width=gear.face_width_m, coupling=fr.model,
        formulation=fr.formulation, boundary=bd.output, law=law, mu0=fr.mu0, v0=fr.v0_m_per_s,
        viscosity=fr.viscosity_Pa_s, roughness_um=fr.roughness_um, v_reg=fr.regularization_m_per_s,
        spring_ratio=bd.stiffness_ratio, spring_zeta=bd.damping_ratio,
        bearings=bearings or Bearings(), per_pair=per_pair)


# ------------------------------------------------------------------------ constitutive laws


def benedict_kelley_us(load_lb_per_in, viscosity_cP, sliding_in_per_s, sum_in_per_s, roughness_uin):
    """``0.0127 C_R log10(3.17e8 W / (eta0 V_s V_e^2))``, ``C_R = 50/(50 - S)``: the original
    US-customary law (W lb/in, eta0 cP, V in/s, S micro-inch), uncapped."""
    c_r = 50.0 / (50.0 - roughness_uin)
    with np.errstate(divide="ignore", invalid="ignore"):
        return 0.0127 * c_r * np.log10(3.17e8 * load_lb_per_in / (viscosity_cP * sliding_in_per_s * sum_in_per_s**2))


def kelley_lemanski_magnitude(load_per_width, viscosity, sliding, rolling, roughness_um, cap=KELLEY_MU_CAP):
    """``|mu|`` from SI inputs: convert to the original units, evaluate, clip to ``[0, cap]``
    (``V_s -> 0``: the logarithm diverges, the cap holds; no load: 0)."""
    w = np.asarray(load_per_width, dtype=float) * METRE_PER_INCH / NEWTON_PER_LBF  # N/m -> lb/in
    eta = viscosity / PA_S_PER_CENTIPOISE
    vs = np.abs(sliding) / METRE_PER_INCH
    ve = np.abs(rolling) / METRE_PER_INCH
    s_uin = roughness_um * 1e-6 / (METRE_PER_INCH * 1e-6)
    mu = benedict_kelley_us(np.where(w > 0, w, 1.0), eta, vs, ve, s_uin)
    mu = np.where((vs == 0) | (ve == 0), np.inf, mu)
    return np.where(w > 0, np.clip(mu, 0.0, cap), 0.0)


def friction_coefficient(p: Parameters, sliding, rolling, load_per_width):
    """Signed ``mu`` (MODEL.md §3); NLTV replaces ``sgn`` by ``(2/pi) atan(V_s / v_reg)``."""
    if p.coupling == "NLTV":
        sign = 2 / math.pi * np.arctan(sliding / p.v_reg)
    else:
        sign = np.sign(sliding)
    if p.law == "none":
        return 0.0 * sliding
    if p.law == "coulomb":
        return p.mu0 * sign
    if p.law == "arctan":
        return 2 * p.mu0 / math.pi * np.arctan(sliding / p.v0)
    if p.law == "kelley-lemanski":
        return sign * kelley_lemanski_magnitude(load_per_width, p.viscosity, sliding, rolling, p.roughness_um)
    raise ValueError(p.law)


def normal_loads(p: Parameters, sigma, x, mesh_force):
    """The friction normal load rule, MODEL.md §11 (rectangular mesh)."""
    n = p.normal_load
    if p.coupling == "LTI" or p.formulation == "A":
        if p.backlash == 0:
            return sigma * n
        return np.where(x > p.backlash / 2, sigma * n, 0.0)
    if p.backlash == 0:
        return sigma * np.abs(mesh_force)
    b = p.backlash / 2
    return np.where(x > b, sigma * np.maximum(mesh_force, 0.0),
                    np.where(x < -b, sigma * np.maximum(-mesh_force, 0.0), 0.0))


def static_pair_loads(k_pairs, offsets, load):
    """§9's quasi-static per-pair loads: ``delta_s`` with ``sum_j k_j max(delta_s - o_j, 0) = N``.

    `k_pairs`, `offsets`: shape ``(pairs, n)``, ``k_j = 0`` for a pair out of the path."""
    order = np.argsort(np.where(k_pairs > 0, offsets, np.inf), axis=0)
    k_sorted = np.take_along_axis(k_pairs, order, 0)
    o_sorted = np.take_along_axis(offsets, order, 0)
    delta = np.full(k_pairs.shape[1], np.nan)
    for m in range(1, k_pairs.shape[0] + 1):
        ks = np.sum(k_sorted[:m], 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            trial = (load + np.sum(k_sorted[:m] * o_sorted[:m], 0)) / ks
        upper = o_sorted[m] if m < k_pairs.shape[0] else np.inf
        upper = np.where(k_sorted[m] > 0, upper, np.inf) if m < k_pairs.shape[0] else upper
        ok = np.isnan(delta) & (ks > 0) & (trial >= o_sorted[m - 1]) & (trial <= upper)
        delta = np.where(ok, trial, delta)
    return k_pairs * np.maximum(delta[None] - offsets, 0.0)


# -------------------------------------------------------------------------------- evaluation


def mesh_kind(p: Parameters) -> str:
    if p.per_pair is not None:
        return "per-pair-backlash" if p.backlash > 0 else "per-pair"
    if p.coupling == "LTI":
        return "lti"
    return "dead-zone" if p.backlash > 0 else "linear"


def _values(p: Parameters, s, omega_p, state) -> dict:
    g, br = p.geometry, p.bearings
    wp, wg = p.speeds(omega_p)
    amp = list(p.ste_amplitude) + [0.0] * (STE_ORDERS - len(p.ste_amplitude))
    ph = list(p.ste_phase) + [0.0] * (STE_ORDERS - len(p.ste_phase))
    assert len(amp) == STE_ORDERS
    values = dict(
        t=s * p.mesh_period(omega_p), W_p=wp, W_g=wg, J_p=p.J_p, J_g=p.J_g, M_p=br.M_p, M_g=br.M_g,
        R_bp=g.Rbp, R_bg=g.Rbg, L=g.L, x_A=g.xA, x_E=g.xE, Z_p=g.teeth_pinion, T_p=p.torque,
        T_g=p.output_torque(state.get("reaction", 0.0)), theta_w=state.get("windup", 0.0), k_b=p.k_b,
        c_b=p.c_b, k_py=br.k_py, c_py=br.c_py, k_px=br.k_px, c_px=br.c_px, k_gy=br.k_gy, c_gy=br.c_gy,
        k_gx=br.k_gx, c_gx=br.c_gx, b=p.backlash / 2, k_mean=p.k_mean, N_load=p.normal_load,
        C_mean=p.mean_compliance if p.per_pair is None else 0.0,
    )
    values |= {f"A_{i + 1}": a for i, a in enumerate(amp)} | {f"ph_{i + 1}": f for i, f in enumerate(ph)}
    for name in COORDINATES:
        values[name] = state[name]
        values["d" + name] = state["d" + name]
    if p.per_pair is not None:
        pp = p.per_pair
        middle = (g.xA + g.xE) / 2
        values |= dict(ca_p=pp.ca_p, xs_p=middle if pp.xs_p is None else pp.xs_p, ca_g=pp.ca_g,
                       xs_g=middle if pp.xs_g is None else pp.xs_g)
    return values


def evaluate(p: Parameters, s, omega_p, state) -> dict:
    """Accelerations of the derivation at mesh phases `s` [-] and pinion speed `omega_p`
    [rad/s] for the physical `state` (arrays ``phi_p, dphi_p, ...``, optional ``windup``
    ``theta_w`` [rad] and ``reaction`` ``T_g/R_bg`` [N]).

    Returns a dict: ``acc`` and ``scale`` (name -> array: the coordinates, ``delta`` and
    ``delta_rotation = R_bp phi_p'' - R_bg phi_g''``, the rigid-bearing limit's ``delta''``),
    per-pair ``mu``, ``normal``, ``vs`` (the sliding velocity the law sees), ``sigma``, and
    ``x = delta - eps``, ``F_mesh``."""
    s = np.asarray(s, dtype=float)
    shape = s.shape
    eq = equations(mesh_kind(p))
    g = p.geometry
    values = _values(p, s, omega_p, state)
    pos = eq("positions", values, shape)
    xi_p = pos[:PAIRS]
    inside = (xi_p >= g.xA) & (xi_p <= g.xE)
    count = np.sum(inside, 0)
    sigma = inside / count
    if p.per_pair is None:
        k = np.where(count == 2, p.k_max, p.k_min)
        c = p.c * k / p.k_mean if (p.damping_model == "proportional" and p.coupling != "LTI") else p.c + 0 * k
        values |= dict(k=k, c=c)
    else:
        k_pairs = np.where(inside, p.per_pair.k_pair(xi_p), 0.0)
        values |= {f"k_{j}": k_pairs[j] for j in range(PAIRS)}
        values |= {f"c_{j}": p.c * k_pairs[j] / p.k_mean for j in range(PAIRS)}
        values |= dict(k=0.0, c=0.0)
        reliefs = eq("relief", values, shape)
        values |= {f"E_{j}": reliefs[j] for j in range(PAIRS)}
        values |= {f"dE_{j}": reliefs[PAIRS + j] for j in range(PAIRS)}
    kin = eq("kinematics", values, shape)
    x, eps = kin[2], kin[3]
    first = 5 + 2 * PAIRS  # after delta, delta', x, eps, eps', xi_p, xi_g
    vs, vs_nom = kin[first:first + PAIRS], kin[first + PAIRS:first + 2 * PAIRS]
    vr, vr_nom = kin[first + 2 * PAIRS:first + 3 * PAIRS], kin[first + 3 * PAIRS:first + 4 * PAIRS]
    mesh_force = kin[first + 4 * PAIRS]
    nonlinear = p.coupling == "NLTV"
    if p.per_pair is None:
        normal = normal_loads(p, sigma, x, mesh_force)
        law_load = normal if nonlinear else sigma * p.normal_load
    else:
        pairs = eq("pairs", values, shape)
        gap, pair_force, relief = pairs[:PAIRS], pairs[PAIRS:2 * PAIRS], reliefs[:PAIRS]
        static = static_pair_loads(k_pairs, eps[None] + relief, p.normal_load)
        if p.formulation == "A":
            drive = gap > 0
            normal = np.where(drive, static, 0.0)
        else:
            # drive flank: max(F_j, 0); back flank (F_j <= 0 there): max(-F_j, 0); apart: F_j = 0
            normal = np.where(gap > 0, np.maximum(pair_force, 0.0), np.maximum(-pair_force, 0.0))
        law_load = normal if nonlinear else static
    sliding = vs if nonlinear else vs_nom
    rolling = vr if nonlinear else vr_nom
    mu = np.where(inside, friction_coefficient(p, sliding, rolling, law_load / p.face_width), 0.0)
    normal = np.where(inside, normal, 0.0)
    values |= {f"mu_{j}": mu[j] for j in range(PAIRS)} | {f"N_{j}": normal[j] for j in range(PAIRS)}
    acc = eq("accelerations", values, shape)
    scale = eq("scales", values, shape)
    names = COORDINATES + ("delta", "delta_rotation")
    out = dict(acc=dict(zip(names, acc)), scale=dict(zip(names, scale)), mu=mu, normal=normal, vs=sliding,
               vs_instantaneous=vs, sigma=sigma, x=x, F_mesh=mesh_force, eps=eps, deps=kin[4], k=values["k"])
    if p.per_pair is not None:
        out |= dict(pair_force=pair_force, gap=gap, relief=relief, relief_rate=reliefs[PAIRS:])
    return out


def static_windup(p: Parameters, omega_p: float, adaptive: bool = False) -> float:
    """``theta_g,s`` [rad] on the soft spring: ``k_b theta_g,s = R_bg (T_p + <T_fp>)/R_bp + <T_fg>``
    (the mean of the pinion and gear equations in the quasi-static state: nominal speeds,
    ``N_j = sigma_j N``). The means between the breakpoints by adaptive quadrature (`adaptive`),
    else by a composite Gauss-Legendre rule (fast; for placing states)."""
    if p.boundary != "spring":
        return 0.0
    g = p.geometry
    wp, wg = p.speeds(omega_p)

    def torque(s):
        s = np.atleast_1d(s)
        xi_p = g.xA + g.pb * (s[None] + np.arange(PAIRS)[:, None])
        xi_g = g.L - xi_p
        inside = (xi_p >= g.xA) & (xi_p <= g.xE)
        sigma = inside / np.sum(inside, 0)
        vs, vr = xi_p * wp - xi_g * wg, xi_p * wp + xi_g * wg
        load = sigma * p.normal_load
        mu = friction_coefficient(p, vs, vr, load / p.face_width)
        t_fp, t_fg = -np.sum(mu * load * xi_p, 0), np.sum(mu * load * xi_g, 0)
        return g.Rbg * t_fp / g.Rbp + t_fg

    edges = p.breakpoints()
    if adaptive:
        mean = sum(integrate.quad(lambda s: float(torque(s)[0]), a, b_, epsabs=0.0, epsrel=1e-13, limit=400)[0]
                   for a, b_ in zip(edges[:-1], edges[1:]))
    else:
        x, w = np.polynomial.legendre.leggauss(16)
        sub = np.linspace(0.0, 1.0, 9)
        lo = (edges[:-1, None] + np.diff(edges)[:, None] * sub[None, :-1]).ravel()
        width = (np.diff(edges)[:, None] * np.diff(sub)[None]).ravel()
        nodes = (lo[:, None] + width[:, None] * (x[None] + 1) / 2).ravel()
        weights = (width[:, None] * w[None] / 2).ravel()
        mean = float(np.sum(weights * torque(nodes)))
    return (g.Rbg * p.torque / g.Rbp + mean) / p.k_b
