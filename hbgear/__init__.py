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

from .build import build_model as build_model  # noqa: E402
from .config import load_config as load_config  # noqa: E402
from .errors import ConfigError as ConfigError, ConvergenceError as ConvergenceError  # noqa: E402
from .friction import Arctan as Arctan, Coulomb as Coulomb, KelleyLemanski as KelleyLemanski  # noqa: E402
from .friction import NoFriction as NoFriction  # noqa: E402
from .geometry import GearPair as GearPair  # noqa: E402
from .model import GearPairModel as GearPairModel  # noqa: E402
from .solve import PeriodicSolution as PeriodicSolution, rpm_to_rad_s as rpm_to_rad_s  # noqa: E402
from .solve import solve_periodic as solve_periodic  # noqa: E402

try:
    __version__ = version("hbgear")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0"
