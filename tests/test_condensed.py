"""The condensed path (a system's ``input_map``: Newton and continuation steps on the ports,
:mod:`hbgear.engine.condensed`) against the dense path, the reference: the Jacobian, the residual
and the bordered solves at a probe state, the continuation curves of the gear pair on bearings
and shafts (6 and 8 DOF, LTV and NLTV), the probe check of a wrong declaration, and a system
written here that is not a gear pair."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hbgear import build_model
from hbgear.config import parse_config, read_toml
from hbgear.engine.system import PeriodicSystem
from hbgear.engine.condensed import as_matrix, check_input_map, lu_factor, lu_solve
from hbgear.engine.continuation import continuation, sweep_method
from hbgear.engine.hb import HarmonicBalance, residual_functions
from hbgear.engine.metric import arclength_sizes, sized_functions_of as _sized_functions_of
from hbgear.engine.system import check_system
from hbgear.gear.solve import rpm_to_rad_s
from hbgear.gear.system import GearSystem

# a failed trace of the compiled corrector falls back to the Python one with a warning: here an error
pytestmark = pytest.mark.filterwarnings("error:jit_step:RuntimeWarning")

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "bearings.toml"
SHAFTS = dict(drive_inertia_kgm2=5e-3, load_inertia_kgm2=1e-2, drive_stiffness_Nm_per_rad=2e5,
              load_stiffness_Nm_per_rad=3e5, damping_ratio=0.02)
H, SAMPLES = 4, 64
COUPLINGS = {"LTV": [], "NLTV": ["friction.model=NLTV", "friction.law=arctan"]}


def gear(dof, coupling, *overrides):
    data = read_toml(EXAMPLE)
    if dof == 8:
        data["shafts"] = dict(SHAFTS)
    return GearSystem(build_model(parse_config(data, list(COUPLINGS[coupling]) + list(overrides))))


def both(system, harmonics=H, samples=SAMPLES):
    """``(dense, condensed)``: each ``(hb, residual_and_jacobians, residual, args)``."""
    out = []
    for operator in ("dense", "condensed"):
        hb = HarmonicBalance(system.ndof, harmonics, 1, samples, operator=operator)
        out.append((hb, *residual_functions(hb, system)))
    return out


CASES = [(6, "LTV", ("mesh.backlash_um=20", "boundary.output=reaction")), (8, "NLTV", ()),
         (6, "LTV", ("boundary.output=torques", "friction.formulation=B"))]


@pytest.mark.parametrize("size", [1, 5, 131])
def test_lu_pair_solves_with_row_exchanges(size):
    """``lu_solve(*lu_factor(a), b)`` (the LU of ``a^T``) solves ``a x = b`` for a matrix whose
    elimination must exchange rows (a zero leading entry, small diagonal): backward error 1e-14."""
    rng = np.random.default_rng(size)
    a = rng.standard_normal((size, size)) + 1e-3 * np.eye(size)
    a[0, 0] = 0.0 if size > 1 else 2.0
    b = rng.standard_normal(size)
    x = np.asarray(jax.jit(lambda a, b: lu_solve(*lu_factor(a), b))(jnp.asarray(a), jnp.asarray(b)))
    scale = np.max(np.sum(np.abs(a), axis=1)) * np.max(np.abs(x)) + np.max(np.abs(b))
    assert np.max(np.abs(a @ x - b)) <= 1e-14 * scale


@pytest.mark.parametrize("dof, coupling, overrides", CASES)
def test_port_jacobian_residual_and_bordered_solve_are_the_dense_ones(dof, coupling, overrides):
    """At a random state (large enough to open a backlash): ``A + U V^T`` is the dense Jacobian,
    the residual and ``dR/dp`` are the dense path's to 1e-12, and the Woodbury solve of the
    bordered system solves the dense bordered matrix (backward error 1e-13)."""
    system = gear(dof, coupling, *overrides)
    (hb, rj_d, _, args_d), (_, rj_c, r_c, args_c) = both(system)
    assert args_d[1].condensed is None and args_c[1].condensed is not None
    p = rpm_to_rad_s(5000.0)
    z = jnp.asarray(np.random.default_rng(0).standard_normal(hb.size))
    r1, j1, p1 = (np.asarray(a) for a in rj_d(z, p, *args_d))
    r2, j2, p2 = rj_c(z, p, *args_c)
    dense = np.asarray(as_matrix(j2))
    assert np.max(np.abs(dense - j1)) <= 1e-12 * np.max(np.abs(j1))
    assert np.max(np.abs(np.asarray(r2) - r1)) <= 1e-12 * np.max(np.abs(r1))
    assert np.max(np.abs(np.asarray(p2) - p1)) <= 1e-12 * np.max(np.abs(p1))
    assert np.allclose(np.asarray(r_c(z, p, *args_c)), np.asarray(r2), rtol=0, atol=1e-13 * np.max(np.abs(r1)))
    rng = np.random.default_rng(1)
    column, row, b = rng.standard_normal(hb.size), rng.standard_normal(hb.size + 1), rng.standard_normal(hb.size + 1)
    x = np.asarray(j2.bordered_factor(jnp.asarray(column), jnp.asarray(row)).solve(jnp.asarray(b)))
    bordered = np.block([[j1, column[:, None]], [row[None]]])
    # normwise backward error (the soft output spring makes the k = 0 block conditioned ~5e5)
    scale = np.max(np.sum(np.abs(bordered), axis=1)) * np.max(np.abs(x)) + np.max(np.abs(b))
    assert np.max(np.abs(bordered @ x - b)) <= 1e-13 * scale


@pytest.mark.parametrize("dof, coupling", [(6, "LTV"), (8, "NLTV")])
def test_continuation_curves_are_the_dense_ones(dof, coupling):
    """The compiled chord corrector on the ports follows the dense LU's curve: the same points
    (parameter and unknowns) to 1e-10 relative while both take the same iterations -- a Newton
    count can flip where a residual lands next to the tolerance (rounding), after which the
    step sizes, not the curve, differ -- and every condensed point is a solution of the dense
    equations: its residual within the tolerance, a dense Newton step from it as small as from
    the dense path's own points."""
    system = gear(dof, coupling)
    p0, p1 = rpm_to_rad_s(4000.0), rpm_to_rad_s(4600.0 if coupling == "NLTV" else 5000.0)
    tolerance = 1e-11
    branches, functions = [], []
    for hb, rj, r, args in both(system):
        functions.append((rj, args))
        branches.append(continuation(rj, r, np.zeros(hb.size), p0, p1, sweep_method(p0, p1, None), args=args,
                                     tolerance=tolerance, progress=False))
    dense, port = branches
    assert dense.success and port.success and len(port.p) > 20
    n = min(len(dense.p), len(port.p))
    flips = (dense.iterations[:n] != port.iterations[:n]) | ~np.isclose(dense.ds[:n], port.ds[:n], rtol=1e-9, atol=0)
    same = int(np.argmax(flips)) if np.any(flips) else n
    if coupling == "LTV":  # linear: one solve per point, nothing to flip
        assert same == len(dense.p) == len(port.p)
    assert same > 20
    scale = np.max(np.abs(dense.z))
    assert np.max(np.abs(dense.p[:same] - port.p[:same])) <= 1e-10 * np.max(np.abs(dense.p))
    assert np.max(np.abs(dense.z[:same] - port.z[:same])) <= 1e-10 * scale
    rj, args = functions[0]

    def newton_steps(branch):  # max|R| and the dense Newton step at each point (dense equations)
        out = []
        for p, z in zip(branch.p, branch.z):
            r, jac, _ = (np.asarray(a) for a in rj(jnp.asarray(z), p, *args))
            out.append((np.max(np.abs(r)), np.max(np.abs(np.linalg.solve(jac, r)))))
        return np.array(out)

    own, other = newton_steps(dense), newton_steps(port)
    assert np.max(other[:, 0]) <= tolerance
    # as close to the dense equations' solutions as the dense path's own points (at 1e-11)
    assert np.max(other[:, 1]) <= max(1e-10 * scale, 2.0 * np.max(own[:, 1]))


def test_port_jacobian_with_moving_contact_events_is_the_dense_one():
    """The relieved ISO pair (contact that opens at state-dependent instants: the event
    functions' moving jumps) on bearings, NLTV: at a state large enough for contact loss the
    events' Jacobian is not zero, and the condensed Jacobian (the gathered convolution part, the
    fixed jumps and the moving ones in the port layout) and residual are the dense path's to
    1e-13."""
    from hbgear.engine import events

    data = read_toml(EXAMPLE.parent / "iso_tip_relief.toml")
    data["bearings"] = {"pinion_stiffness_MN_per_m": 500.0, "gear_stiffness_MN_per_m": 500.0, "damping_ratio": 0.02}
    system = GearSystem(build_model(parse_config(data, list(COUPLINGS["NLTV"]))))
    (hb, rj_d, _, args_d), (_, rj_c, _, args_c) = both(system)
    assert args_c[1].condensed is not None and system.nonlinear_force_uses_displacement
    p = rpm_to_rad_s(6000.0)
    z = jnp.asarray(np.random.default_rng(0).standard_normal(hb.size))
    x, extra = hb._split(system, z)
    xc, vc = x.reshape(system.ndof, hb.block), hb._velocity(x, system, p).reshape(system.ndof, hb.block)
    moving = events.jump_jacobian(system, p, extra, xc, vc, hb.harmonics, hb.nu, hb.samples)
    assert np.max(np.abs(np.asarray(moving[0]))) > 0.0 and np.max(np.abs(np.asarray(moving[1]))) > 0.0
    r1, j1, _ = (np.asarray(a) for a in rj_d(z, p, *args_d))
    r2, j2, _ = rj_c(z, p, *args_c)
    assert np.max(np.abs(np.asarray(as_matrix(j2)) - j1)) <= 1e-13 * np.max(np.abs(j1))
    assert np.max(np.abs(np.asarray(r2) - r1)) <= 1e-13 * np.max(np.abs(r1))


def test_auto_takes_the_condensed_path_only_where_it_pays():
    """``operator="auto"``: the 8-DOF pair at H = 32 is condensed, the 2-DOF pair (nothing to
    condense at 130 unknowns) and any system without an input map stay dense."""
    system = gear(8, "LTV")
    assert HarmonicBalance(8, 32, 1, 256).prepare(system).condensed is not None
    assert HarmonicBalance(8, 32, 1, 256).prepare(gear(8, "NLTV")).condensed is not None  # 4 ports: 262 of 520
    assert HarmonicBalance(8, 32, 1, 256, operator="dense").prepare(system).condensed is None
    data = read_toml(EXAMPLE)
    del data["bearings"]
    rigid = GearSystem(build_model(parse_config(data)))
    assert HarmonicBalance(2, 32, 1, 256).prepare(rigid).condensed is None
    assert GearSystem(system.model, parameter="torque_pinion_Nm").input_map(1.0) is None


def test_a_wrong_input_map_is_refused():
    """NLTV friction sees the centre and rotation speeds: declaring only ``delta`` breaks the
    promise, and the probe says so (``check_system`` and the forced condensed path)."""

    @jax.tree_util.register_dataclass
    @dataclasses.dataclass(frozen=True)
    class OnlyDelta(GearSystem):
        def input_map(self, p):
            return np.eye(self.ndof)[:1]

    honest = gear(8, "NLTV")
    check_input_map(honest, rpm_to_rad_s(5000.0))
    wrong = OnlyDelta(honest.model)
    with pytest.raises(ValueError, match="input_map"):
        check_system(wrong, rpm_to_rad_s(5000.0))
    with pytest.raises(ValueError, match="input_map"):
        HarmonicBalance(8, H, 1, SAMPLES, operator="condensed").prepare(wrong)


def test_a_wrong_output_map_is_refused():
    """LTV friction of formulation B (loaded by the dynamic mesh force) sees only ``delta`` but acts
    on the rotations and the centres: declaring the outputs as ``delta`` alone breaks the
    promise, and the probe says so."""

    @jax.tree_util.register_dataclass
    @dataclasses.dataclass(frozen=True)
    class OutputsDelta(GearSystem):
        def output_map(self, p):
            return np.eye(self.ndof)[:1]

    honest = gear(8, "LTV", "friction.formulation=B")
    check_input_map(honest, rpm_to_rad_s(5000.0))
    assert honest.input_map(1.0).shape[0] == 1 and honest.output_map(1.0).shape[0] == 4
    wrong = OutputsDelta(honest.model)
    with pytest.raises(ValueError, match="output_map"):
        check_system(wrong, rpm_to_rad_s(5000.0))
    with pytest.raises(ValueError, match="output_map"):
        HarmonicBalance(8, H, 1, SAMPLES, operator="condensed").prepare(wrong)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Chain(PeriodicSystem):
    """Four masses in a chain on springs and dampers, the first with a parametric cubic spring to
    the ground and a harmonic force: only ``q[0]`` is seen by the non-LTI force."""

    forcing: float = 1.0
    ndof = 4
    is_linear = False
    coefficients_independent_of_parameter = True

    def mass_matrix(self, p, xp=np):
        return xp.diag(xp.asarray([1.0, 2.0, 1.5, 1.0]))

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        k, c = 1.0, 0.03
        spring = [-(k * (q[0] - q[1]) + c * (qd[0] - qd[1]))]
        for i in (1, 2):
            spring.append(k * (q[i - 1] - q[i]) + c * (qd[i - 1] - qd[i])
                          - k * (q[i] - q[i + 1]) - c * (qd[i] - qd[i + 1]))
        spring.append(k * (q[2] - q[3]) + c * (qd[2] - qd[3]) - 0.5 * q[3] - c * qd[3])
        ground = -(1.0 + 0.3 * xp.cos(2 * np.pi * s)) * q[0] + self.forcing * xp.cos(2 * np.pi * s)
        linear = xp.stack([spring[0] + ground] + spring[1:])
        nonlinear = xp.stack([-0.2 * q[0] ** 3] + [0.0 * q[0]] * 3)
        return {"linear": linear, "nonlinear": nonlinear, "all": linear + nonlinear}[part]

    def input_map(self, p):
        return np.eye(4)[:1]


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class ChainOnTwo(Chain):
    """:class:`Chain` whose cubic spring pulls on the second mass too: the non-LTI force sees
    ``q[0]`` and acts on ``q[0]`` and ``q[1]`` (not by virtual work), declared or not."""

    outputs: tuple | None = dataclasses.field(default=None, metadata=dict(static=True))

    def force(self, s, q, qd, p, part, extra, xp=np):
        out = super().force(s, q, qd, p, part, extra, xp)
        if part == "linear":
            return out
        return out + xp.stack([0.0 * q[0], 0.1 * q[0] ** 3, 0.0 * q[0], 0.0 * q[0]])

    def output_map(self, p):
        return None if self.outputs is None else np.eye(4)[list(self.outputs)]


@pytest.mark.parametrize("system, outputs", [(Chain(), 4), (ChainOnTwo(), 4), (ChainOnTwo(outputs=(0, 1)), 2)],
                         ids=["outputs-undeclared", "not-reciprocal", "two-outputs"])
def test_a_system_that_is_not_a_gear_pair(system, outputs):
    """The engine knows nothing of gears: a chain with one nonlinear, parametric port, continued
    on the dense and on the condensed path (forced: it is small), gives the same curve, with
    the outputs declared (two of the four coordinates) or not (all four)."""
    check_system(system, 1.0)
    branches = []
    for operator in ("dense", "condensed"):
        hb = HarmonicBalance(4, 5, 1, 64, operator=operator)
        rj, r, args = residual_functions(hb, system)
        assert (args[1].condensed is not None) == (operator == "condensed")
        if operator == "condensed":
            assert args[1].condensed.outputs.shape == (outputs, 4)
        branches.append(continuation(rj, r, np.zeros(hb.size), 0.6, 1.4, sweep_method(0.6, 1.4, None), args=args,
                                     tolerance=1e-11, progress=False))
    dense, port = branches
    assert dense.success and port.success and len(dense.p) == len(port.p) > 10
    assert np.max(np.abs(dense.z - port.z)) <= 1e-10 * np.max(np.abs(dense.z))


def test_the_arclength_scaling_is_the_dense_paths():
    """The spring's mean wind-up counted in its own units (``arclength_mean_scales``, the NLTV pair
    on the soft output spring) on the condensed path as on the dense one: the scaled
    ``PortJacobian`` is ``R_z diag(sizes)`` to 1e-12, and the continuation in ``z / sizes``
    (the ``frc`` sweep's unknowns) follows the dense path's curve to 1e-10 while both take the same
    iterations (as in :func:`test_continuation_curves_are_the_dense_ones`)."""
    system = gear(8, "NLTV")
    p0, p1 = rpm_to_rad_s(4000.0), rpm_to_rad_s(4300.0)
    runs = []
    for hb, _, _, args in both(system):
        sizes = arclength_sizes(hb, system, p0)
        assert sizes is not None and np.max(sizes) > 1e3
        srj, sr = _sized_functions_of(hb)
        runs.append((hb, srj, sr, (*args, jnp.asarray(sizes))))
    (hb, srj_d, _, args_d), (_, srj_c, _, args_c) = runs
    assert args_c[1].condensed is not None
    y = jnp.asarray(np.random.default_rng(0).standard_normal(hb.size)) / args_d[-1]
    p = rpm_to_rad_s(5000.0)
    r1, j1, _ = (np.asarray(a) for a in srj_d(y, p, *args_d))
    r2, j2, _ = srj_c(y, p, *args_c)
    assert hasattr(j2, "bordered_factor")  # the port form, scaled (not the dense matrix)
    assert np.max(np.abs(np.asarray(as_matrix(j2)) - j1)) <= 1e-12 * np.max(np.abs(j1))
    assert np.max(np.abs(np.asarray(r2) - r1)) <= 1e-12 * np.max(np.abs(r1))
    branches = [continuation(srj, sr, np.zeros(hb.size), p0, p1, sweep_method(p0, p1, None), args=args,
                             tolerance=1e-11, progress=False) for _, srj, sr, args in runs]
    dense, port = branches
    assert dense.success and port.success and len(port.p) > 20
    n = min(len(dense.p), len(port.p))
    flips = (dense.iterations[:n] != port.iterations[:n]) | ~np.isclose(dense.ds[:n], port.ds[:n], rtol=1e-9, atol=0)
    same = int(np.argmax(flips)) if np.any(flips) else n
    assert same > 20
    assert np.max(np.abs(dense.p[:same] - port.p[:same])) <= 1e-10 * np.max(np.abs(dense.p))
    assert np.max(np.abs(dense.z[:same] - port.z[:same])) <= 1e-10 * np.max(np.abs(dense.z))
