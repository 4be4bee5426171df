"""The spur-gear pair with tooth friction (MODEL.md), as a system of :mod:`hbgear.engine`.

Geometry, friction laws, the model and its adaptor to the engine, exact and variational
monodromy, time integration and the read-outs a gear engineer looks at. It imports the engine
and nothing from the config, the outputs or the CLI.
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)  # hbgear computes in float64 (see hbgear.engine)
