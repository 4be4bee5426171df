"""Arrays handed to compiled programs without a compiled program of their own.

Outside a trace, ``jnp.asarray(x)`` of a numpy array runs a small compiled program (JAX's
``stage``) for every new shape and dtype: 0.03-0.2 s the first time in a process (compiled, or
loaded from the disk cache). ``jax.device_put`` copies the array to the device without one.
"""

from __future__ import annotations

import jax
import numpy as np

__all__ = ["device_array"]


def device_array(x):
    """`x` as a JAX array: a JAX array or a tracer as it is, anything else converted by numpy
    (its dtype kept) and put on the device (:func:`jax.device_put`)."""
    if isinstance(x, jax.Array):
        return x
    return jax.device_put(np.asarray(x))
