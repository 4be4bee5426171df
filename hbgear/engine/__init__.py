"""The generic machinery for any periodic system ``M q'' = Q(s, q, q'; p)``.

Harmonic balance (:mod:`.hb`), Newton (:mod:`.newton`), arc-length continuation
(:mod:`.continuation`), Floquet stability by Hill's method (:mod:`.floquet`, :mod:`.hill`), on
the contract of :mod:`.system`. Nothing here knows about gears: it imports nothing from
:mod:`hbgear.gear`, the config, the outputs or the CLI.
"""
