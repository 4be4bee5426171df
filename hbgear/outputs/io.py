"""The one place that writes output files; every write is atomic.

Each writer streams into a temporary file in the destination's directory, flushes and
fsyncs it, then renames it over the destination with :func:`os.replace`. If anything raises
on the way (including a row generator or a plotting call), the temporary file is removed
and the exception propagates: an interrupted or failed run never leaves a truncated file.

**Public API:** :func:`write_text_atomic`, :func:`write_json_atomic`,
:func:`write_csv_atomic`, :func:`save_figure_atomic`, :func:`prepare_out_dir`.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import enum
import json
import math
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..errors import ConfigError

__all__ = [
    "prepare_out_dir",
    "save_figure_atomic",
    "to_jsonable",
    "write_csv_atomic",
    "write_json_atomic",
    "write_text_atomic",
]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def _atomic(path: str | os.PathLike, mode: str = "w") -> Iterator[IO]:
    """Open a temporary sibling of `path`; on clean exit fsync and rename it onto `path`."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        kwargs = {"encoding": "utf-8", "newline": ""} if "b" not in mode else {}
        with os.fdopen(fd, mode, **kwargs) as fh:
            fd = -1  # now owned by fh
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if fd != -1:
            os.close(fd)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    """Best effort: make the rename itself durable (not possible on every platform)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    """Write `text` (UTF-8) to `path` atomically. **Returns:** the path."""
    with _atomic(path) as fh:
        fh.write(text)
    return Path(path)


def to_jsonable(obj: Any) -> Any:
    """Plain JSON types from `obj`: numpy scalars/arrays, tuples, dataclasses, enums and
    paths are converted; non-finite floats (nan, inf) become `None` (JSON `null`)."""
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, enum.Enum):
        return to_jsonable(obj.value)
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, Mapping):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, set, frozenset)):
        return [to_jsonable(v) for v in obj]
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(dataclasses.asdict(obj))
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    # jax arrays and other array-likes
    try:
        array = np.asarray(obj)
    except Exception:  # noqa: BLE001 -- fall through to a clear TypeError
        array = None
    if array is not None and array.dtype != object:
        return to_jsonable(array)
    raise TypeError(f"cannot write a {type(obj).__name__} to JSON: {obj!r}")


def write_json_atomic(path: str | os.PathLike, obj: Any) -> Path:
    """Write `obj` as indented JSON atomically (see :func:`to_jsonable`; nan -> null).

    **Raises:** `TypeError` for objects that have no JSON form (nothing is written).
    """
    text = json.dumps(to_jsonable(obj), indent=2, allow_nan=False) + "\n"
    return write_text_atomic(path, text)


def _cell(value: Any) -> Any:
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, np.integer):
        return int(value)
    return value


def write_csv_atomic(
    path: str | os.PathLike, header: Sequence[str], rows: Iterable[Sequence[Any]]
) -> Path:
    """Write a CSV file atomically: one header line, then one line per row.

    Floats are written with full (repr) precision, `nan`/`inf` as such, booleans as 1/0.
    `rows` may be a generator; it is consumed while writing.

    **Raises:** `ValueError` if a row's length differs from the header's (nothing written).
    """
    header = list(header)
    with _atomic(path) as fh:
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        for number, row in enumerate(rows, start=1):
            row = list(row)
            if len(row) != len(header):
                raise ValueError(
                    f"{path}: row {number} has {len(row)} values, header has {len(header)}"
                )
            writer.writerow([_cell(v) for v in row])
    return Path(path)


def save_figure_atomic(fig: Any, path: str | os.PathLike, **savefig_kwargs: Any) -> Path:
    """Save a matplotlib figure atomically; the format comes from the suffix of `path`
    unless `format=` is given. Other keyword arguments go to `Figure.savefig`."""
    path = Path(path)
    fmt = savefig_kwargs.pop("format", None) or path.suffix.lstrip(".").lower() or "png"
    with _atomic(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **savefig_kwargs)
    return path


def prepare_out_dir(path: str | os.PathLike) -> Path:
    """Create the output directory (with parents) if needed and check it is writable.

    **Raises:** `ConfigError("--out", path, "a writable directory ...")`.
    """
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise ConfigError("--out", str(path), f"a writable directory ({reason})") from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise ConfigError("--out", str(path), "a writable directory (permission denied)")
    return out
