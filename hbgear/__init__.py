"""hbgear: steady-state vibration of spur-gear pairs with tooth friction, by harmonic balance.

The physics follows Vaishya & Singh (2003), *Strategies for Modeling Friction in Gear Dynamics*
(``docs/MODEL.md``). Typical use::

    import hbgear
    model = hbgear.build_model(hbgear.load_config("examples/paper_table1.toml"))
    sol = hbgear.solve(model, speed_rpm=3000.0, harmonics=32)
    curve = hbgear.frequency_response(model, speed_rpm=(3000.0, 20000.0))
    curve.plot()

Any periodic system: subclass :class:`hbgear.PeriodicSystem` and call the same functions with
``parameter=``. Names are loaded on first use, so ``import hbgear`` is cheap and changes no
process-wide setting; :mod:`hbgear.runtime` sets up the one-thread XLA runtime and the disk
compilation cache on request (the ``hbgear`` command does). hbgear computes in float64: the
first use of its engine turns on JAX's ``jax_enable_x64``.
"""

from __future__ import annotations

import importlib

#: Public name -> module that defines it (imported on first access).
_EXPORTS = {
    "solve": "api", "frequency_response": "api", "simulate": "api", "stability_map": "api",
    "natural_frequencies": "api",
    "FrequencyResponse": "api", "SystemFrequencyResponse": "api",
    "study": "studies", "load_study": "studies", "StudyResult": "studies",
    "load_config": "config", "parse_config": "config", "RunConfig": "config",
    "build_model": "build",
    "ConfigError": "errors", "ConvergenceError": "errors",
    "PeriodicSystem": "engine.system", "Duffing": "engine.system", "check_system": "engine.system",
    "HarmonicBalance": "engine.hb",
    "hill_multipliers": "engine.floquet", "is_stable": "engine.floquet",
    "Branch": "engine.continuation", "PseudoArclength": "engine.continuation", "continuation": "engine.continuation",
    "GearPairModel": "gear.model", "GearSystem": "gear.system", "GearPair": "gear.geometry",
    "Coulomb": "gear.friction", "Arctan": "gear.friction", "KelleyLemanski": "gear.friction",
    "NoFriction": "gear.friction",
    "PeriodicSolution": "gear.solve", "solve_periodic": "gear.solve", "rpm_to_rad_s": "gear.solve",
    "rad_s_to_rpm": "gear.solve",
}
_SUBMODULES = ("runtime", "api", "config", "build", "errors", "engine", "gear", "outputs", "cli", "studies", "tasks")

__all__ = sorted(_EXPORTS) + ["runtime", "__version__"]



def _version() -> str:
    """The installed distribution's version (read on first use: ``importlib.metadata`` is slow to import)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hbgear")
    except PackageNotFoundError:  # pragma: no cover - running from a source tree
        return "0.0.0"


def __getattr__(name: str):
    if name == "__version__":
        value = globals()["__version__"] = _version()
        return value
    if name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'hbgear' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_EXPORTS) | set(_SUBMODULES))
