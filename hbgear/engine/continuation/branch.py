"""What a continuation run returns: the :class:`Branch` of stored points, its :class:`Status`
(with :data:`MESSAGES`) and the :class:`PointKind` of each point."""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

__all__ = ["Branch", "MESSAGES", "PointKind", "Status"]


class Status(enum.IntEnum):
    """Overall outcome of a continuation run (see :data:`MESSAGES`)."""

    SUCCESS = 0  # reached p_end
    MAX_POINTS = 1  # max_points reached before p_end
    STEP_TOO_SMALL = 2  # no acceptable step with ds >= ds_min
    START_FAILED = 3  # Newton at p0 did not converge
    TURNED_BACK = 4  # the branch went back past p0
    STOPPED = 5  # the callback asked to stop


MESSAGES = {
    Status.SUCCESS: "reached the end of the parameter range",
    Status.MAX_POINTS: "stopped at max_points before the end of the range; raise max_points or ds_max",
    Status.STEP_TOO_SMALL: "no acceptable continuation step above ds_min; try more harmonics, a smaller "
    "ds_min, more corrector iterations or a smoother model",
    Status.START_FAILED: "the starting point did not converge; give a better z0",
    Status.TURNED_BACK: "the branch turned back past the start of the range (an isola or a branch that "
    "does not reach p_end)",
    Status.STOPPED: "stopped by the callback",
}


class PointKind(enum.IntEnum):
    """What a stored branch point is."""

    START = 0
    REGULAR = 1
    FOLD = 2  # located turning point (p-component of the tangent ~ 0)
    END = 3  # solved exactly at p_end



@dataclass(frozen=True)
class Branch:
    """A continued branch: an immutable struct of arrays, points in path order.

    **Fields:** `p` (n,) parameter; `z` (n, size) unknowns; `kind` (n,) :class:`PointKind`;
    `iterations` (n,) corrector iterations; `residual` (n,) ``max |R|``; `tangent_p` (n,)
    ``p``-component of the unit tangent in scaled units (its sign is the direction of travel in
    ``p``; it changes sign at folds); `ds` (n,) arclength step that reached the point;
    `status` :class:`Status`; `message`; `parameter_scale` ``p_ref``; `rejected` steps refused;
    `start_seconds` the wall time of the start (with `jit_step`: the compilation of the corrector
    on its first use, then Newton at ``p0`` and the first tangent).
    """

    p: np.ndarray
    z: np.ndarray
    kind: np.ndarray
    iterations: np.ndarray
    residual: np.ndarray
    tangent_p: np.ndarray
    ds: np.ndarray
    status: Status
    message: str
    parameter_scale: float
    rejected: int = 0
    start_seconds: float = 0.0

    def __post_init__(self):
        for name in ("p", "z", "kind", "iterations", "residual", "tangent_p", "ds"):
            value = np.array(getattr(self, name))
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.p)

    @property
    def success(self) -> bool:
        return self.status == Status.SUCCESS

    @property
    def folds(self) -> np.ndarray:
        """Indices of the located fold points."""
        return np.flatnonzero(self.kind == PointKind.FOLD)

    @property
    def fold_p(self) -> np.ndarray:
        return self.p[self.folds]

