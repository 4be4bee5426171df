"""The generic machinery for any periodic system ``M q'' = Q(s, q, q'; p)``.

Harmonic balance (:mod:`.hb`), Newton (:mod:`.newton`), arc-length continuation
(:mod:`.continuation`), Floquet stability by Hill's method (:mod:`.floquet`, :mod:`.hill`), on
the contract of :mod:`.system`. Nothing here knows about gears: it imports nothing from
:mod:`hbgear.gear`, the config, the outputs or the CLI.

hbgear computes in float64: importing the engine turns on JAX's ``jax_enable_x64`` (the one
process-wide JAX setting it needs; a program that wants JAX's float32 default elsewhere should run
hbgear in another process). Thread pools, CPU affinity and the compilation cache are left as they
are (:mod:`hbgear.runtime` sets them up on request; the CLI asks).
"""

import jax as _jax

_jax.config.update("jax_enable_x64", True)
