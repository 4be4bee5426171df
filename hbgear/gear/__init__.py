"""The spur-gear pair with tooth friction (MODEL.md), as a system of :mod:`hbgear.engine`.

Geometry, friction laws, the model and its adaptor to the engine, exact and variational
monodromy, time integration and the read-outs a gear engineer looks at. It imports the engine
and nothing from the config, the outputs or the CLI. The geometry and the tooth-contact library
(:mod:`.geometry`, :mod:`.contact`) need no JAX; the model switches JAX to float64 when imported.
"""
