"""`hbgear stability-map CONFIG`: max |Floquet multiplier| over speed x contact ratio.

Grid from ``[map]`` (``k_max`` and ``k_min`` held as the contact ratio varies). One unit of
work is one contact ratio (a row of the map, :func:`compute_row`): linear models (LTI, LTV A
or B) use the batched exact monodromy of :mod:`hbgear.engine.floquet`, others harmonic balance +
Hill's method at every speed.

Runs locally by default. With ``map.scheduler`` in the config or ``--scheduler ADDRESS``, the
rows are Dask futures on that cluster (``dask.distributed.Client(ADDRESS)``; needs
``pip install hbgear[distributed]``).

Resuming: every finished row is appended to ``stability.partial.csv`` in the output directory
(flushed and fsynced per row; its first line is a fingerprint of the configuration and the
grid; the record and the local/Dask execution are :mod:`hbgear.tasks`). Re-running the same command skips the rows found there; ``--fresh`` ignores them. At the
end ``stability.csv`` (``speed_rpm, contact_ratio, max_abs_floquet``) and ``stability.png`` are
written atomically and the partial file is removed.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from . import Command, register
from ..errors import ConfigError

if TYPE_CHECKING:  # numpy is imported where it is used: --help and bad input answer without it
    import numpy as np

__all__ = ["STABILITY_MAP", "compute_row", "grid", "run_map"]

HEADER = ("speed_rpm", "contact_ratio", "max_abs_floquet")
PARTIAL = "stability.partial.csv"

def grid(config) -> tuple[np.ndarray, np.ndarray]:
    """``(speeds_rpm, contact_ratios)`` of ``[map]``."""
    import numpy as np

    m = config.map
    speeds = np.linspace(m.speed_rpm_start, m.speed_rpm_stop, int(m.speed_steps))
    ratios = np.linspace(m.contact_ratio_start, m.contact_ratio_stop, int(m.contact_ratio_steps))
    return speeds, ratios


def compute_row(config, contact_ratio: float, speeds_rpm) -> np.ndarray:
    """max |multiplier| at every speed for one contact ratio (the task sent to workers)."""
    import numpy as np

    from ..build import model_at_contact_ratio
    from ..gear.maps import stability_row

    so = config.solver
    model = model_at_contact_ratio(config, float(contact_ratio))
    values = stability_row(model, np.asarray(speeds_rpm, float), harmonics=int(so.harmonics or 24),
                           nu=int(so.subharmonic), samples=int(so.time_samples))
    return np.asarray(values, dtype=float)


# ----------------------------------------------------------------------------- partial file


def _fingerprint(config, speeds, ratios) -> str:
    from ..outputs.io import to_jsonable
    from ..tasks import fingerprint

    data = to_jsonable(config.to_dict())
    data.get("map", {}).pop("scheduler", None)
    data["grid"] = {"speeds_rpm": [repr(float(s)) for s in speeds], "contact_ratios": [repr(float(g)) for g in ratios]}
    return fingerprint("stability-map", data)


def _row_lines(ratio: float, speeds, values) -> str:
    return "".join(f"{float(s)!r},{float(ratio)!r},{float(v)!r}\n" for s, v in zip(speeds, values))


class _RowCodec:
    """The partial file's rows: ``speed_rpm,contact_ratio,max_abs_floquet`` per point; a task (the
    index of a contact ratio) counts as finished when all its speeds are there."""

    header = ",".join(HEADER)

    def __init__(self, speeds, ratios):
        self.speeds, self.ratios = speeds, ratios

    def encode(self, i: int, values) -> str:
        return _row_lines(self.ratios[i], self.speeds, values)

    def decode(self, lines) -> dict[int, np.ndarray]:
        import numpy as np

        index = {float(g): i for i, g in enumerate(self.ratios)}
        column = {float(s): k for k, s in enumerate(self.speeds)}
        found: dict[int, dict[int, float]] = {}
        for line in lines:
            parts = line.split(",")
            if len(parts) != 3:
                continue
            try:
                s, g, v = (float(x) for x in parts)
            except ValueError:
                continue
            if g in index and s in column:
                found.setdefault(index[g], {})[column[s]] = v
        n = len(self.speeds)
        return {i: np.array([row[k] for k in range(n)]) for i, row in found.items() if len(row) == n}


# ----------------------------------------------------------------------------- running


def run_map(config, out_dir: Path, *, scheduler: str | None = None, fresh: bool = False, progress: bool = True):
    """Compute the map (resuming from the partial file) and write the outputs.

    **Returns:** ``(speeds_rpm, contact_ratios, values)`` with values of shape
    ``(len(contact_ratios), len(speeds_rpm))``.
    """
    import numpy as np

    from ..outputs.io import write_csv_atomic
    from ..tasks import Journal, run_tasks

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    speeds, ratios = grid(config)
    journal = Journal(out_dir / PARTIAL, _fingerprint(config, speeds, ratios), _RowCodec(speeds, ratios))
    tasks = {i: (config, ratios[i], speeds) for i in range(len(ratios))}
    done = run_tasks(compute_row, tasks, journal=journal, done={} if fresh else journal.read(), scheduler=scheduler,
                     progress=progress, desc="stability-map", unit="row", scheduler_key="map.scheduler")
    values = np.stack([np.asarray(done[i], dtype=float) for i in range(len(ratios))])
    write_csv_atomic(
        out_dir / "stability.csv",
        HEADER,
        ((float(s), float(g), float(values[i, k])) for i, g in enumerate(ratios) for k, s in enumerate(speeds)),
    )
    from ..outputs.io import save_figure_atomic
    from ..outputs.plots import stability_map_figure

    save_figure_atomic(stability_map_figure(speeds, ratios, values, title=_title(config)), out_dir / "stability.png",
                       dpi=130)
    journal.remove()
    return speeds, ratios, values


def _title(config) -> str:
    f = config.friction
    return (
        f"max |Floquet multiplier| per mesh period: {f.model}-{f.formulation}, {f.law} mu0={f.mu0:g}, "
        f"zeta={config.mesh.damping_ratio:g}, boundary {config.boundary.output}"
    )


# ----------------------------------------------------------------------------- command


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler address (e.g. tcp://host:8786): one task per contact ratio; "
        "overrides map.scheduler",
    )
    parser.add_argument("--fresh", action="store_true", help="ignore rows left by an interrupted run")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _scheduler(config, args) -> str | None:
    return args.scheduler if getattr(args, "scheduler", None) else config.map.scheduler


def _validate(config, args) -> None:
    address = _scheduler(config, args)
    key = "--scheduler" if getattr(args, "scheduler", None) else "map.scheduler"
    if address is not None:
        if not isinstance(address, str) or not address.strip():
            raise ConfigError(key, address, 'a Dask scheduler address such as "tcp://host:8786"')
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise ConfigError(key, address, "a Dask scheduler needs dask.distributed: install hbgear[distributed]") from None


def _run(config, args, out_dir: Path) -> int:
    import numpy as np

    speeds, ratios, values = run_map(
        config, out_dir, scheduler=_scheduler(config, args), fresh=args.fresh, progress=not args.no_progress
    )
    bad = int(np.sum(~np.isfinite(values)))
    unstable = int(np.sum(values > 1.0 + 1e-9))
    print(
        f"stability map: {len(ratios)} contact ratios x {len(speeds)} speeds, {unstable} unstable points, "
        f"max |multiplier| {np.nanmax(values) if np.isfinite(values).any() else math.nan:.6g} -> {out_dir}",
        file=sys.stderr,
    )
    if bad:
        print(f"hbgear: warning: {bad} points did not converge (nan in stability.csv)", file=sys.stderr)
    return 0


STABILITY_MAP = register(
    Command(
        name="stability-map",
        help="max |Floquet multiplier| over speed x contact ratio ([map]) -> stability.csv, stability.png",
        add_arguments=_add_arguments,
        run=_run,
        validate=_validate,
    ),
    replace=True,
)
