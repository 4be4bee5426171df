"""hbgear: steady-state vibration of a spur-gear pair with tooth friction by harmonic balance.

The physics follows Vaishya & Singh (2003), *Strategies for Modeling Friction in Gear
Dynamics*; see ``docs/MODEL.md``. Typical use::

    from hbgear import load_config, build_model, solve_periodic, rpm_to_rad_s
    model = build_model(load_config("examples/paper_table1.toml"))
    solution = solve_periodic(model, rpm_to_rad_s(3000), harmonics=32)
    print(solution.summary()["dte_rms_um"])
"""

from importlib.metadata import PackageNotFoundError, version

import jax as _jax

_jax.config.update("jax_enable_x64", True)


def _enable_compilation_cache() -> None:
    """Keep compiled XLA programs on disk across runs (``HBGEAR_CACHE_DIR``; ``HBGEAR_NO_CACHE=1`` disables).

    A frequency-response curve spends most of a short run compiling the residual; with the
    cache a second run of the same problem size starts at once.
    """
    import os
    from pathlib import Path

    if os.environ.get("HBGEAR_NO_CACHE"):
        return
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hbgear" / "jax"
    path = Path(os.environ.get("HBGEAR_CACHE_DIR", default))
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return
    _jax.config.update("jax_compilation_cache_dir", str(path))
    _jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)


_enable_compilation_cache()


def _single_threaded_runtime() -> None:
    """Run compiled programs on one XLA thread (``HBGEAR_RUNTIME_THREADS=default`` keeps JAX's).

    A corrector step is ~340 small kernels (131 unknowns at H = 32); XLA:CPU hands independent
    ones to an intra-op thread pool with one thread per CPU, and on small kernels the hand-offs
    and work stealing cost more than they win (2 cores: a point 1.0-1.3 ms with the pool,
    0.7 ms with one thread). JAX sizes that pool from the process's CPU affinity when it creates
    its CPU client, so the client is created here under a one-CPU affinity, which is then
    restored for this thread and for every thread made meanwhile. Compilation is not affected
    (its threads are made later, with the full affinity). Linux only; a no-op when the JAX
    backend already exists (JAX imported and used before hbgear).
    """
    import os

    setting = os.environ.get("HBGEAR_RUNTIME_THREADS", "1").strip().lower()
    if setting not in ("1", "default"):
        import warnings

        warnings.warn(f"HBGEAR_RUNTIME_THREADS = {setting!r}: expected '1' or 'default'; using '1'",
                      RuntimeWarning, stacklevel=2)
    if setting == "default" or not hasattr(os, "sched_setaffinity"):
        return
    try:
        from jax._src import xla_bridge

        if xla_bridge.backends_are_initialized():
            return
        original = os.sched_getaffinity(0)
    except Exception:  # pragma: no cover - a JAX without this hook: keep its default
        return
    if len(original) < 2:
        return

    def threads():
        try:
            return set(os.listdir("/proc/self/task"))
        except OSError:  # pragma: no cover
            return set()

    before = threads()
    try:
        os.sched_setaffinity(0, {min(original)})
        _jax.devices()
    except Exception:  # pragma: no cover - no usable backend: JAX reports it at first use
        pass
    finally:
        for tid in [0, *(int(t) for t in threads() - before)]:
            try:
                os.sched_setaffinity(tid, original)
            except OSError:  # pragma: no cover - the thread has ended, or the mask is refused
                pass


_single_threaded_runtime()

from .build import build_model as build_model  # noqa: E402
from .engine.continuation import Branch as Branch, PseudoArclength as PseudoArclength  # noqa: E402
from .config import load_config as load_config  # noqa: E402
from .errors import ConfigError as ConfigError, ConvergenceError as ConvergenceError  # noqa: E402
from .gear.friction import Arctan as Arctan, Coulomb as Coulomb, KelleyLemanski as KelleyLemanski  # noqa: E402
from .gear.friction import NoFriction as NoFriction  # noqa: E402
from .gear.geometry import GearPair as GearPair  # noqa: E402
from .gear.model import GearPairModel as GearPairModel  # noqa: E402
from .gear.solve import PeriodicSolution as PeriodicSolution, rpm_to_rad_s as rpm_to_rad_s  # noqa: E402
from .gear.solve import solve_periodic as solve_periodic  # noqa: E402
from .gear.system import GearSystem as GearSystem  # noqa: E402
from .engine.system import Duffing as Duffing  # noqa: E402

try:
    __version__ = version("hbgear")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"
