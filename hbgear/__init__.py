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

from .build import build_model as build_model  # noqa: E402
from .continuation import Branch as Branch, PseudoArclength as PseudoArclength  # noqa: E402
from .config import load_config as load_config  # noqa: E402
from .errors import ConfigError as ConfigError, ConvergenceError as ConvergenceError  # noqa: E402
from .friction import Arctan as Arctan, Coulomb as Coulomb, KelleyLemanski as KelleyLemanski  # noqa: E402
from .friction import NoFriction as NoFriction  # noqa: E402
from .geometry import GearPair as GearPair  # noqa: E402
from .model import GearPairModel as GearPairModel  # noqa: E402
from .solve import PeriodicSolution as PeriodicSolution, rpm_to_rad_s as rpm_to_rad_s  # noqa: E402
from .solve import solve_periodic as solve_periodic  # noqa: E402
from .system import Duffing as Duffing, GearSystem as GearSystem  # noqa: E402

try:
    __version__ = version("hbgear")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"
