"""Compiled programs told apart by class (hbgear.engine.typed_jit): jax >= 0.7 compares the tree
structures of two ``register_dataclass`` classes with the same leaves as equal, and ``jax.jit``'s
cache can then hand one class the program traced for the other."""

from __future__ import annotations

from dataclasses import dataclass, make_dataclass
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
from jax.tree_util import register_dataclass

from hbgear.engine.hb import HarmonicBalance
from hbgear.engine.system import PeriodicSystem
from hbgear.engine.typed_jit import node_types, typed_jit


def _classes(count, fields=(("x", float, 1.0),), base=(), namespace=None):
    """`count` frozen dataclasses with the same fields, each with its own class constant ``factor = i``."""
    made = []
    for i in range(count):
        cls = make_dataclass(f"Same{i}", list(fields), bases=base, frozen=True, namespace=dict(namespace or {}))
        cls.factor = float(i)
        made.append(register_dataclass(cls))
    return made


def test_each_class_runs_its_own_program():
    """100 one-field classes through one compiled function: every call sees its own class (plain
    ``jax.jit`` on jax 0.10.2 gave 7 to 13 of them another class's program, five processes)."""
    f = typed_jit(lambda s, y: s.x * type(s).factor + y)
    classes = _classes(100)
    got = np.array([float(f(cls(), 0.0)) for cls in classes])
    np.testing.assert_array_equal(got, np.arange(100.0))


def test_node_types_names_every_node_class_and_static_arguments_are_not_walked():
    outer = make_dataclass("Outer", [("inner", object), ("y", float)], frozen=True)
    register_dataclass(outer)
    (inner,) = _classes(1)
    assert node_types(outer(inner(), 2.0)) == (outer, inner)
    assert node_types((1.0, jnp.ones(3))) == (tuple,)
    g = typed_jit(lambda scale, s: s.x * scale, static_argnums=0)
    assert float(g(3.0, inner(x=2.0))) == 6.0
    bound = g.typed_for(3.0, inner(x=2.0))
    assert float(bound(3.0, inner(x=5.0))) == 15.0


@dataclass(frozen=True)
class _Oscillator(PeriodicSystem):
    r"""``x'' + c x' + k x + g x^3 = cos(w t)`` with ``k`` a class constant: classes that differ
    only there have the same tree structure."""

    ndof: ClassVar[int] = 1
    is_linear: ClassVar[bool] = False
    stiffness: ClassVar[float] = 1.0

    def mass_matrix(self, p, xp=np):
        return xp.ones((1, 1))

    def excitation_frequency(self, p):
        return p

    def force(self, s, q, qd, p, part, extra, xp=np):
        linear = xp.cos(2 * np.pi * s) - self.stiffness * q[0] - self.damping * qd[0]
        cubic = -self.cubic * q[0] ** 3
        return xp.stack([linear if part == "linear" else cubic if part == "nonlinear" else linear + cubic])


@register_dataclass
@dataclass(frozen=True)
class _Reference(_Oscillator):
    """The same equations with ``k`` a leaf: one class, one program, the value an argument."""

    damping: float = 0.1
    cubic: float = 0.5
    k: float = 1.0

    @property
    def stiffness(self):
        return self.k


def test_harmonic_balance_residuals_follow_the_class():
    """Oscillator classes with equal leaves and their own stiffness (a class constant): the
    residual of each equals that of one reference class carrying the stiffness as a leaf."""
    hb = HarmonicBalance(1, 2, 1, 8)
    z = jnp.asarray(np.random.default_rng(3).normal(size=hb.size) * 0.3)
    classes = _classes(12, fields=(("damping", float, 0.1), ("cubic", float, 0.5)), base=(_Oscillator,))
    for cls in classes:
        cls.stiffness = 1.0 + 0.1 * cls.factor
        ours, reference = cls(), _Reference(k=cls.stiffness)
        np.testing.assert_allclose(np.asarray(hb.residual(z, 0.9, ours)), np.asarray(hb.residual(z, 0.9, reference)),
                                   rtol=0, atol=1e-13)


def test_compiled_entry_points_that_take_a_system_are_typed():
    """Every compiled function of the engine that takes a system as a traced argument goes
    through typed_jit (the test above can only catch a collision by chance)."""
    from hbgear.engine import events, hill, monodromy, structured
    from hbgear.engine.continuation.compiled import _cached_jit_corrector

    hb = HarmonicBalance(1, 2, 1, 8)
    entry_points = [hb._residual_jit, hb._residual_and_jacobian_jit, hb._residual_and_jacobians_jit,
                    hb._residual_and_port_jacobians_jit, hb._hill_matrices_jit, structured._linearize_jit,
                    events.crossings_compiled, monodromy._variational_rhs(False), monodromy._variational_rhs(True),
                    hill._pencil_function(hb, False), hill._pencil_function(hb, True)]
    for function in entry_points:
        assert hasattr(function, "typed_for"), function
