"""Compiled programs told apart by class (hbgear.engine.typed_jit): jax 0.10 compares the tree
structures of two ``register_dataclass`` classes with the same leaves as equal, and ``jax.jit``'s
cache can then hand one class the program traced for the other."""

from __future__ import annotations

from dataclasses import make_dataclass

import jax.numpy as jnp
import numpy as np
from jax.tree_util import register_dataclass

from hbgear.engine.hb import HarmonicBalance
from hbgear.engine.system import Duffing
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


def test_harmonic_balance_residuals_follow_the_class():
    """Duffing subclasses with Duffing's leaves whose only difference is a class constant, the
    excitation frequency ``w = f_i p``: the residual of each at ``p`` equals Duffing's at ``f_i p``."""
    hb = HarmonicBalance(1, 2, 1, 8)
    z = jnp.asarray(np.random.default_rng(3).normal(size=hb.size) * 0.3)
    for cls in _classes(12, fields=(), base=(Duffing,)):
        cls.excitation_frequency = lambda self, p: (1.0 + 0.1 * type(self).factor) * p
        np.testing.assert_allclose(np.asarray(hb.residual(z, 0.9, cls())),
                                   np.asarray(hb.residual(z, 0.9 * (1.0 + 0.1 * cls.factor), Duffing())),
                                   rtol=0, atol=1e-13)


def test_compiled_entry_points_that_take_a_system_are_typed():
    """Every compiled function of the engine that takes a system as a traced argument goes
    through typed_jit (the test above can only catch a collision by chance)."""
    from hbgear.engine import events, hill, monodromy, structured
    from hbgear.engine.continuation.compiled import _cached_jit_corrector
    from hbgear.engine.hb import residual_functions

    hb = HarmonicBalance(1, 2, 1, 8)
    corrector = _cached_jit_corrector(*residual_functions(hb, Duffing())[:2], hb.size)[0]
    entry_points = [corrector, hb._residual_jit, hb._residual_and_jacobian_jit, hb._residual_and_jacobians_jit,
                    hb._residual_and_port_jacobians_jit, hb._hill_matrices_jit, structured._linearize_jit,
                    events.crossings_compiled, monodromy._variational_rhs(False), monodromy._variational_rhs(True),
                    hill._pencil_function(hb, False), hill._pencil_function(hb, True)]
    for function in entry_points:
        # programs kept on disk (hbgear.engine.persistent) wrap the typed function; their key has the classes
        assert hasattr(getattr(function, "persisted", function), "typed_for"), function
