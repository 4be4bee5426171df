r"""Natural frequencies of the gear pair's linear time-invariant model, to name the resonances of a curve.

The model at its mean mesh stiffness (``k(t) -> k_mean``), without friction and damping, is
``M q'' + K q = 0`` with ``M = P^T M_r P`` (:mod:`hbgear.gear.dofs`) and ``K = -dQ/dq`` of the same
model's own generalised force (it is affine in ``q``: one evaluation per coordinate gives ``K``
exactly, to rounding). Its modes solve ``K v = w^2 M v`` (symmetric, ``M`` positive definite). A
free rotation (``"reaction"``) is a zero eigenvalue and is left out; the ``"spring"`` boundary's soft
mode is kept and named.

Each mode is named by where its strain energy sits: the mesh (``k_mean delta^2``), a bearing
direction, a shaft, the soft output spring -- the element holding the largest share -- and
reported with the shares and the kinetic energy per body. A mesh order ``r`` excites mode ``f`` near
the pinion speed ``n = 60 f / (r Z_p)`` rpm (the Campbell diagram's crossings).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Modes", "natural_frequencies", "stiffness_matrix"]

#: Strain-energy elements by coordinate: the coordinate's name -> label.
_ELEMENTS = {"delta": "mesh", "u": "output spring", "y_p": "pinion LOA bearing", "x_p": "pinion OLOA bearing",
             "y_g": "gear LOA bearing", "x_g": "gear OLOA bearing", "t_d": "drive shaft", "t_l": "load shaft"}
#: Bodies of the kinetic energy by physical coordinate.
_BODIES = {"a_p": "pinion rotation", "a_g": "gear rotation", "a_d": "drive inertia", "a_l": "load inertia",
           "y_p": "pinion LOA", "x_p": "pinion OLOA", "y_g": "gear LOA", "x_g": "gear OLOA"}


def _mean_stiffness_model(model):
    """The model with ``k(t) = k_mean``, no friction, no STE and no damping (linear, time-invariant)."""
    from dataclasses import replace

    from .friction import NoFriction
    from .mesh import RectangularMesh

    k = model.k_mean_N_per_m  # of any mesh (per pair: its own); the constant k_mean is the rectangular one
    changes = dict(k_max_N_per_m=k, k_min_N_per_m=k, damping_ratio=0.0 * model.damping_ratio, friction=NoFriction(),
                   ste_amplitude_m=np.zeros(0), ste_phase_rad=np.zeros(0), spring_damping_ratio=0.0, coupling="LTV",
                   formulation="A", contact="linear", damping_model="constant", mesh=RectangularMesh())
    if model.bearings is not None:
        changes["bearings"] = replace(model.bearings, damping_ratio=0.0)
    if model.shafts is not None:
        changes["shafts"] = replace(model.shafts, damping_ratio_drive=0.0, damping_ratio_load=0.0)
    return model.replace(**changes)


def stiffness_matrix(model) -> np.ndarray:
    """``K = -dQ/dq`` [N/m] of the mean-stiffness model (:func:`_mean_stiffness_model`), ``(ndof, ndof)``:
    the generalised force is affine in ``q``, so ``K e_j = Q(0) - Q(h e_j)`` divided by ``h``, exact to
    rounding. The soft spring's static wind-up is a constant term and drops out."""
    lti = _mean_stiffness_model(model)
    n = lti.ndof
    s = np.array([0.25])
    h = float(lti.normal_load_N / lti.k_mean_N_per_m)
    zero = np.zeros((n, 1))
    base = np.asarray(lti.generalized_force(s, zero, zero, 1.0), dtype=float)[:, 0]
    k = np.empty((n, n))
    for j in range(n):
        q = zero.copy()
        q[j] = h
        k[:, j] = (base - np.asarray(lti.generalized_force(s, q, zero, 1.0), dtype=float)[:, 0]) / h
    return k


@dataclass(frozen=True)
class Modes:
    """Undamped modes of the mean-stiffness model.

    **Fields:** `frequencies_hz` ``(m,)`` ascending; `shapes` ``(ndof, m)`` (mass-normalised, ``q``
    coordinates); `names` (the element with the largest strain-energy share); `strain_shares` and
    `kinetic_shares` (per mode: element / body -> share of the mode's energy); `coordinates`.
    """

    frequencies_hz: np.ndarray
    shapes: np.ndarray
    names: tuple
    strain_shares: tuple
    kinetic_shares: tuple
    coordinates: tuple

    def __len__(self) -> int:
        return len(self.frequencies_hz)

    def resonance_speeds_rpm(self, teeth_pinion: float, orders) -> np.ndarray:
        """``n = 60 f / (r Z_p)`` [rpm] for each mode (rows) and mesh order ``r`` (columns)."""
        r = np.asarray(orders, dtype=float)
        return 60.0 * self.frequencies_hz[:, None] / (r[None] * float(teeth_pinion))

    def records(self, teeth_pinion: float | None = None, orders=(1, 2, 3)) -> list[dict]:
        """JSON-ready records (``modes.json``): frequency, name, shares and, given `teeth_pinion`, the
        speeds where mesh orders `orders` meet the mode."""
        out = []
        for i, f in enumerate(self.frequencies_hz):
            rec = {"index": i, "frequency_hz": float(f), "name": self.names[i],
                   "strain_energy_shares": {k: float(v) for k, v in self.strain_shares[i].items()},
                   "kinetic_energy_shares": {k: float(v) for k, v in self.kinetic_shares[i].items()}}
            if teeth_pinion is not None:
                speeds = self.resonance_speeds_rpm(teeth_pinion, orders)[i]
                rec["resonance_speed_rpm"] = {f"order_{r:g}": float(v) for r, v in zip(orders, speeds)}
            out.append(rec)
        return out


def natural_frequencies(model) -> Modes:
    """The undamped modes of `model` at mean mesh stiffness (module docstring), numpy/scipy.

    **Raises:** ``ValueError`` if ``K`` is not symmetric to rounding (an assembly error) or has a
    negative eigenvalue beyond rounding."""
    from scipy.linalg import eigh

    lti = _mean_stiffness_model(model)
    k = stiffness_matrix(model)
    m = np.asarray(lti.mass_matrix(), dtype=float)
    scale = float(np.max(np.abs(k)))
    if np.max(np.abs(k - k.T)) > 1e-9 * scale:
        raise ValueError(f"stiffness matrix not symmetric: {np.max(np.abs(k - k.T)):.3g} of {scale:.3g}")
    w2, v = eigh(0.5 * (k + k.T), m)
    floor = 1e-9 * float(np.max(np.abs(w2)))
    if np.min(w2) < -floor:
        raise ValueError(f"negative eigenvalue {np.min(w2):.3g} of K v = w^2 M v")
    keep = w2 > floor  # the free rotation of the reaction boundary
    w2, v = w2[keep], v[:, keep]
    names, strain, kinetic = [], [], []
    lay = lti.layout
    coords = lay.coordinates
    kq = np.diag(k)  # every element acts on its own coordinate: the strain energy is diagonal
    rows = lti.projection()
    masses = lti.physical_masses()
    for j in range(v.shape[1]):
        e = kq * v[:, j] ** 2
        shares = {_ELEMENTS[c]: e[i] / np.sum(e) for i, c in enumerate(coords) if kq[i] > 0}
        names.append(max(shares, key=shares.get))
        strain.append(shares)
        r = {name: sum(float(c) * v[i, j] for i, c in enumerate(row)) for name, row in rows.items()}
        t = {_BODIES[name]: float(masses[name]) * r[name] ** 2 for name in r}
        total = sum(t.values())
        kinetic.append({name: value / total for name, value in t.items()})
    return Modes(np.sqrt(w2) / (2 * math.pi), v, tuple(names), tuple(strain), tuple(kinetic), coords)
