"""engine.arrays.device_array, and the engine's entry points handing numpy unknowns to compiled
functions without staging them through a compiled program of their own (JAX's ``stage``: one
per new shape, 0.03-0.2 s each the first time in a process)."""

import logging

import jax
import numpy as np
import pytest

from hbgear.engine.arrays import device_array
from hbgear.engine.hb import HarmonicBalance
from hbgear.engine.response import newton_solve
from hbgear.engine.system import Duffing


@pytest.fixture
def compiled_programs():
    """The names of the programs JAX compiles while the test runs (its compile log)."""
    names: list[str] = []

    class Names(logging.Handler):
        def emit(self, record):
            message = record.getMessage()
            if message.startswith("Compiling "):
                names.append(message.split()[1])

    handler, logger = Names(level=logging.DEBUG), logging.getLogger("jax")
    logger.addHandler(handler)
    previous = jax.config.jax_log_compiles
    jax.config.update("jax_log_compiles", True)
    try:
        yield names
    finally:
        jax.config.update("jax_log_compiles", previous)
        logger.removeHandler(handler)


def test_device_array_keeps_values_and_dtype_and_compiles_nothing(compiled_programs):
    for value in (np.linspace(0.0, 1.0, 37), np.arange(41, dtype=np.int32), np.ones((3, 43))):
        out = device_array(value)
        assert isinstance(out, jax.Array) and out.dtype == value.dtype
        np.testing.assert_array_equal(np.asarray(out), value)
    already = device_array(np.zeros(47))
    assert device_array(already) is already
    assert compiled_programs == []


def test_compile_log_sees_a_staged_array(compiled_programs):
    """The fixture catches the regression the test below guards against: ``jnp.asarray`` of a new
    shape is logged as a compiled ``stage`` (where this jax stages arrays at all; older releases
    copy them directly, and then there is nothing to guard)."""
    import jax.numpy as jnp

    if not hasattr(jax.lax, "stage"):
        pytest.skip("this jax copies arrays without a staging program")
    jnp.asarray(np.zeros((53, 7)))
    assert compiled_programs == ["jit(stage)"]


def test_newton_from_numpy_stages_no_array(compiled_programs):
    """A Newton solve from a numpy start (H = 11: 23 unknowns, a size no other test uses) compiles
    its residual functions and nothing that stages the unknowns. Its full steps are evaluated
    with the Jacobian (kept when taken): where no step is halved, as here, the residual-only
    program is never compiled (a first solve of the relieved ISO pair at H = 48: one program of
    ~20 s instead of two)."""
    hb, system = HarmonicBalance(1, 11, 1, 64), Duffing()
    result = newton_solve(hb, system, 0.8, np.zeros(hb.size))
    assert result.converged
    assert compiled_programs == ["jit(_residual_and_jacobians_jit)"]
