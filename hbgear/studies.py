"""Studies: one frequency-response curve per sample of varied config keys (``[study]``).

A sample is the base config with its overrides applied to the TOML document (a list entry
``key[i]`` replaces that entry of the base list) and validated by the normal loader, then the
curve ``hbgear frc`` computes for it (:func:`hbgear.api.frc_curve`: same ``[sweep]``, ``[solver]``
and defaults). A sample the loader rejects -- a drawn value out of range, say -- is a row with
``success = 0`` and the loader's message; draws are never clipped. A curve whose continuation
stops early, or that does not converge, is a row with ``success = 0`` and the solver's message
(the metrics of the curve so far are kept).

:func:`study` runs the samples (:func:`hbgear.tasks.run_tasks`: local processes, this process or
a Dask cluster) with a resumable record in the output directory, and :func:`load_study` reads
``study.json`` / ``study.csv`` back. Both return a :class:`StudyResult`.

Grid samples: every combination of the values, in the order of ``[study.parameters]`` with the
last key varying fastest. Monte Carlo samples: each key's values are drawn from its own
generator, ``numpy.random.default_rng([seed, crc32(key)])``, so they depend only on the seed,
the key and the number of samples (``lognormal = [mu, sigma]`` is of ``ln x``).
"""

from __future__ import annotations

import copy
import itertools
import json
import math
import os
import platform
import socket
import sys
import time
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .config import RunConfig, StudyConfig, apply_overrides, parse_config, read_toml
from .errors import ConfigError, ConvergenceError

__all__ = ["METRICS", "RECORD", "RESULT_COLUMNS", "StudyResult", "draw_samples", "load_study", "run_sample",
           "study"]

#: The curve's numbers in ``study.csv``, after ``sample`` and the varied keys: the peak of the
#: DTE peak-to-peak on the ``nu`` branch and its speed, the largest dynamic factor there, the
#: unstable zones (linear models: the exact scan's, as in ``frc.json``; otherwise runs of
#: consecutive unstable curve points), unstable points, folds, located period doublings, points.
METRICS = ("peak_dte_p2p_um", "peak_speed_rpm", "max_dynamic_factor", "unstable_zones", "unstable_points", "folds",
           "period_doublings", "points")
#: The status columns of ``study.csv``.
STATUS_COLUMNS = ("success", "status", "message")
#: The columns of ``study.csv`` after ``sample`` and the varied keys: INTERFACE.md's first, then the rest.
RESULT_COLUMNS = (*METRICS[:4], "success", *METRICS[4:], "status", "message")
#: The resumable record in the output directory (removed when the study is complete).
RECORD = "study.partial.jsonl"
OUTPUTS = ("study.csv", "study.json", "study.png")


# ----------------------------------------------------------------------------- samples


def _draw(parameter, n: int, seed: int) -> list:
    """`n` draws of one Monte Carlo parameter from its own generator."""
    rng = np.random.default_rng([seed, zlib.crc32(parameter.key.encode())])
    name, args = parameter.distribution, parameter.arguments
    if name == "choice":
        return [copy.deepcopy(args[i]) for i in rng.integers(0, len(args), n)]
    draw = {"normal": rng.normal, "uniform": rng.uniform, "lognormal": rng.lognormal}[name]
    return [float(v) for v in draw(args[0], args[1], n)]


def draw_samples(definition: StudyConfig) -> list[dict[str, Any]]:
    """The samples of a study: ``[{key: value}]``, in sample order (see the module docstring)."""
    keys = [p.key for p in definition.parameters]
    if definition.kind == "grid":
        return [dict(zip(keys, combo)) for combo in itertools.product(*(p.values for p in definition.parameters))]
    columns = [_draw(p, definition.samples, definition.seed) for p in definition.parameters]
    return [dict(zip(keys, values)) for values in zip(*columns)]


def _check_targets(base: Mapping, definition: StudyConfig, defaults: Mapping | None = None) -> None:
    """Every ``key[i]`` names an entry of a list of the base config, and a list-valued key
    without an index is given whole lists, or numbers when its list has at most one entry (a
    number ``x`` then stands for the list ``[x]``: :func:`sample_data`; INTERFACE.md's
    ``"mesh.ste_amplitude_um" = { normal = [1.0, 0.2] }``). `defaults`: the parsed base config's
    ``to_dict()``, for keys the base document leaves out."""
    for p in definition.parameters:
        current = base.get(p.section, {}).get(p.name)
        if current is None and defaults is not None:
            current = defaults.get(p.section, {}).get(p.name)
        if p.index is None:
            values = p.values if p.distribution is None else p.arguments if p.distribution == "choice" else (0.0,)
            if isinstance(current, (list, tuple)) and len(current) <= 1:
                continue  # a number is the one-entry list [x]
            if isinstance(current, list) and not all(isinstance(v, list) for v in values):
                raise ConfigError(f'study.parameters."{p.key}"', list(values) if p.distribution is None else
                                  {p.distribution: list(p.arguments)},
                                  f"whole lists for the list {p.key}, or one entry of it: "
                                  f'"{p.key}[0]" = ... (entry 0, mesh order 1 for the STE)')
            continue
        if not isinstance(current, list) or p.index >= len(current):
            n = len(current) if isinstance(current, list) else 0
            raise ConfigError(f'study.parameters."{p.key}"', current,
                              f"an entry of the list {p.section}.{p.name} of the base config ({n} entries: index 0.."
                              f"{n - 1}); give the list in the config, e.g. {p.name} = [1.0]")


def _assignments(definition: StudyConfig, sample: Mapping) -> list[tuple]:
    return [(p.section, p.name, p.index, sample[p.key]) for p in definition.parameters]


#: Config keys whose value is a list (a number drawn for one of them is the one-entry list).
LIST_KEYS = {("mesh", "ste_amplitude_um"), ("mesh", "ste_phase_deg")}


def sample_data(base: Mapping, assignments) -> dict:
    """The TOML document of one sample: `base` (without ``[study]``) with each
    ``(section, key, index, value)`` set (``index``: that entry of the base list; a number for a
    list-valued key without an index: the one-entry list ``[value]``, the STE phases padded with
    zeros to its length, their default, unless the phases are varied too)."""
    data = copy.deepcopy(dict(base))
    data.pop("study", None)
    for section, name, index, value in assignments:
        table = data.setdefault(section, {})
        listed = isinstance(table.get(name), list) or (section, name) in LIST_KEYS
        if index is None and listed and not isinstance(value, (list, tuple)):
            table[name] = [copy.deepcopy(value)]
        elif index is None:
            table[name] = copy.deepcopy(value)
        else:
            entries = list(table[name])
            entries[index] = copy.deepcopy(value)
            table[name] = entries
    mesh, varied = data.get("mesh"), {(section, name) for section, name, _, _ in assignments}
    if isinstance(mesh, dict) and ("mesh", "ste_phase_deg") not in varied:
        amplitudes, phases = mesh.get("ste_amplitude_um"), mesh.get("ste_phase_deg")
        if isinstance(amplitudes, list) and isinstance(phases, list) and len(phases) < len(amplitudes):
            mesh["ste_phase_deg"] = phases + [0.0] * (len(amplitudes) - len(phases))
    return data


def toml_value(value: Any) -> str:
    """`value` in TOML syntax (what ``--set section.key=...`` takes)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isfinite(value):
            return repr(value)
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"no TOML form for {type(value).__name__}: {value!r}")


def set_arguments(base: Mapping, assignments) -> list[str]:
    """The ``--set`` arguments that make ``hbgear frc`` run this sample."""
    data = sample_data(base, assignments)
    keys = dict.fromkeys((section, name) for section, name, _, _ in assignments)
    return [f"{section}.{name}={toml_value(data[section][name])}" for section, name in keys]


# ----------------------------------------------------------------------------- one sample


def _plain(obj: Any) -> Any:
    """`obj` as JSON types (NaN kept), exactly as a record read back from the journal is."""

    def default(o):
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        raise TypeError(f"{type(o).__name__} is not JSON")

    return json.loads(json.dumps(obj, default=default))


def _runs(flags) -> int:
    """Number of runs of consecutive True values."""
    flags = np.asarray(flags, dtype=bool)
    return int(np.sum(flags[1:] & ~flags[:-1]) + flags[:1].sum()) if flags.size else 0


def curve_record(curve) -> dict:
    """The study record of a gear curve (:class:`hbgear.api.FrequencyResponse`): :data:`METRICS`
    over the ``nu`` branch, status, message, zones, period doublings, folds."""
    n = curve.points
    p2p, dyn, stable = curve.dte_p2p_um[:n], curve.dynamic_factor[:n], curve.stable[:n]
    peak = int(np.argmax(p2p)) if n else 0
    scanned = bool(curve.model.is_linear and n > 1)
    unstable = stable == 0
    return {
        "success": bool(curve.success), "status": curve.response.status.name.lower(), "message": curve.response.message,
        "peak_dte_p2p_um": float(p2p[peak]) if n else math.nan,
        "peak_speed_rpm": float(curve.speed_rpm[peak]) if n else math.nan,
        "max_dynamic_factor": float(np.max(dyn)) if n else math.nan,
        "unstable_zones": len(curve.unstable_zones) if scanned else _runs(unstable),
        "unstable_points": int(unstable.sum()), "folds": len(curve.folds),
        "period_doublings": len(curve.period_doublings), "points": n, "harmonics": curve.harmonics,
        "unstable_zones_rule": "the exact scan's zones (linear model)" if scanned else
        "runs of consecutive unstable curve points", "zones": curve.unstable_zones,
        "period_doubling": curve.period_doublings, "fold_speeds_rpm": [float(v) for v in curve.folds],
    }


def _failure(status: str, error: Exception) -> dict:
    return {"success": False, "status": status, "message": " ".join(str(error).split()),
            **{k: math.nan for k in METRICS[:3]}, **{k: 0 for k in METRICS[3:]}, "zones": [], "period_doubling": [],
            "fold_speeds_rpm": []}


def run_sample(base: Mapping, assignments, options: Mapping | None = None) -> dict:
    """One sample (the task sent to workers): its config validated by the loader and the physics
    checks, then its curve. **Returns:** a JSON-plain record (:func:`curve_record`, or
    ``success`` False with the loader's or solver's message) with ``seconds``,
    ``compile_seconds`` (:class:`hbgear.tasks.CompileClock`), ``worker`` and, with option
    ``curves``, the ``frc.csv`` columns as ``curve``."""
    from .tasks import CompileClock

    options = dict(options or {})
    t0 = time.perf_counter()
    with CompileClock() as clock:
        try:
            from .api import frc_curve
            from .build import check_config

            config = parse_config(sample_data(base, assignments))
            check_config(config)
            curve = frc_curve(config, progress=False)
            record = curve_record(curve)
            if options.get("curves"):
                from .gear.response import COLUMNS

                record["curve"] = {k: curve.table[k] for k in COLUMNS}
        except ConfigError as error:
            record = _failure("invalid", error)
        except ConvergenceError as error:
            record = _failure("not_converged", error)
    record |= {"seconds": time.perf_counter() - t0, "compile_seconds": clock.seconds,
               "worker": f"{socket.gethostname()}:{os.getpid()}"}
    return _plain(record)


# ----------------------------------------------------------------------------- the result


def _cell(value: Any) -> Any:
    """A varied key's value in ``study.csv`` (lists and tables in TOML syntax)."""
    return toml_value(value) if isinstance(value, (list, tuple, Mapping)) else value


@dataclass(frozen=True)
class StudyResult:
    """A study's samples and results.

    **Fields:** `definition` (the ``[study]`` table); `keys` (the varied keys, the columns after
    ``sample``); `samples` (per sample ``{key: value}``); `records` (per sample: :data:`METRICS`,
    ``success``, ``status``, ``message``, ``zones``, ``period_doubling``, ``set`` (the ``--set``
    arguments of the same ``hbgear frc`` run), ``seconds``, ``compile_seconds``, ``worker``);
    `info` (timings, execution, provenance, config).

    **Use:** ``len(result)``; ``result["peak_dte_p2p_um"]`` or ``result.peak_dte_p2p_um`` (an
    array per column of ``study.csv``; a varied key by its name, ``result["mesh.damping_ratio"]``);
    :meth:`rows` (the ``study.csv`` rows as dicts); :meth:`to_dataframe`; :meth:`plot`;
    :meth:`curve` (a sample's ``frc.csv`` columns, when the study kept them).
    """

    definition: dict
    keys: tuple
    samples: list
    records: list
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.samples)

    @property
    def kind(self) -> str:
        return self.definition.get("kind", "grid")

    @property
    def columns(self) -> tuple[str, ...]:
        """The columns of ``study.csv``."""
        return ("sample", *self.keys, *RESULT_COLUMNS)

    def rows(self) -> list[dict]:
        """The ``study.csv`` rows (``success`` 1/0)."""
        rows = []
        for i, (s, r) in enumerate(zip(self.samples, self.records)):
            row = {"sample": i, **{k: _cell(s[k]) for k in self.keys}, **{k: r[k] for k in RESULT_COLUMNS}}
            rows.append(row | {"success": int(bool(r["success"]))})
        return rows

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "sample":
            return np.arange(len(self))
        if name in self.keys:
            values = [s[name] for s in self.samples]
            numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
            return np.array(values, dtype=float) if numeric else np.array(values, dtype=object)
        if name in METRICS:
            return np.array([math.nan if r[name] is None else r[name] for r in self.records], dtype=float)
        if name == "success":
            return np.array([bool(r["success"]) for r in self.records])
        if name in STATUS_COLUMNS:
            return np.array([r[name] for r in self.records], dtype=object)
        raise KeyError(f"{name!r}: not a column of this study ({', '.join(self.columns)})")

    def __getattr__(self, name: str):
        if name in METRICS or name in STATUS_COLUMNS:
            return self[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    def to_dataframe(self):
        """The ``study.csv`` table as a :class:`pandas.DataFrame` (pandas is not a dependency)."""
        from .api import dataframe

        return dataframe({c: [row[c] for row in self.rows()] for c in self.columns})

    def curve(self, sample: int) -> dict:
        """The ``frc.csv`` columns of `sample` (``{column: array}``), when the study kept curves."""
        record = self.records[sample]
        if "curve" not in record:
            raise KeyError(f"sample {sample}: no curve kept (run the study with curves=True / --curves)")
        return {k: np.array(v, dtype=float) for k, v in record["curve"].items()}

    def plot(self, metric: str = "peak_dte_p2p_um"):
        """Matplotlib figure (``study.png``): grid -- `metric`, the largest dynamic factor and the
        unstable zones against the first varied key, one line per value of the others; Monte Carlo -- `metric`
        against each varied key and its histogram. Failed samples are left out (counted in the title)."""
        from .outputs.plots import study_figure

        values = {k: self[k] for k in self.keys}
        metrics = {m: self[m] for m in dict.fromkeys((metric, "max_dynamic_factor", "unstable_zones"))}
        failed = int((~self.success).sum())
        title = (f"{self.kind.replace('_', ' ')} study: {len(self)} samples" + (f", {failed} failed" if failed else "")
                 + (f" ({Path(self.info['config_file']).name})" if self.info.get("config_file") else ""))
        return study_figure(self.kind, values, metrics, self.success, title)


# ----------------------------------------------------------------------------- running


def _base_document(config, overrides) -> tuple[dict, str | None]:
    if isinstance(config, RunConfig):
        base, source = config.to_dict(), None
    elif isinstance(config, Mapping):
        base, source = copy.deepcopy(dict(config)), None
    elif isinstance(config, (str, os.PathLike)):
        base, source = read_toml(config), os.fspath(config)
    else:
        raise TypeError("study() takes a config file path, a TOML-shaped dict or a RunConfig, "
                        f"not {type(config).__name__}")
    base = apply_overrides(base, list(overrides))
    if source is not None:  # relative file names are the config file's, as load_config reads them
        mesh = base.get("mesh")
        if isinstance(mesh, dict) and isinstance(mesh.get("pair_stiffness_file"), str):
            name = Path(mesh["pair_stiffness_file"])
            mesh["pair_stiffness_file"] = str(name if name.is_absolute() else Path(source).parent / name)
    return base, source


def _fingerprint(config: RunConfig, samples: list) -> str:
    from .outputs.io import to_jsonable
    from .tasks import fingerprint

    data = to_jsonable(config.to_dict())
    data["study"].pop("scheduler", None)
    data["samples"] = [{k: toml_value(v) for k, v in s.items()} for s in samples]
    return fingerprint("study", data)


def _open_record(journal, resume: bool, fresh: bool) -> dict:
    """The finished samples to keep, by the rule of ``--resume`` / ``--fresh``."""
    state = journal.state()
    if fresh or state == "absent":
        return {}
    if state == "other":
        raise ConfigError(str(journal.path), "a record of another study",
                          "a record of this study (same config and [study]) to resume; --fresh discards it, or "
                          "choose another --out")
    done = journal.read()
    if not resume:
        raise ConfigError(str(journal.path), f"an interrupted run of this study ({len(done)} samples finished)",
                          "--resume to continue it or --fresh to start again")
    return done


def _provenance(source, overrides, fingerprint, started) -> dict:
    from . import __version__

    versions = {"hbgear": __version__, "python": platform.python_version(), "numpy": np.__version__}
    if "jax" in sys.modules:
        versions["jax"] = sys.modules["jax"].__version__
    return {"versions": versions, "platform": platform.platform(), "host": socket.gethostname(),
            "config_file": source, "overrides": list(overrides), "fingerprint": fingerprint.rsplit("=", 1)[-1],
            "started_utc": started, "finished_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}


def _timings(records: list, computed: int, wall: float) -> dict:
    seconds = sum(r["seconds"] for r in records)
    compiling = sum(r["compile_seconds"] for r in records)
    return {"wall": wall, "samples_computed": computed, "samples_resumed": len(records) - computed,
            "samples_per_minute": 60.0 * computed / wall if wall > 0 else math.nan, "sample_seconds": seconds,
            "compile_seconds": compiling, "compile_fraction": compiling / seconds if seconds > 0 else math.nan}


def study(config, *, out: str | os.PathLike | None = None, overrides=(), resume: bool = False, fresh: bool = False,
          workers: int | None = None, scheduler: str | None = None, progress=None, curves: bool = False) -> StudyResult:
    """Run the study of a config's ``[study]`` section: one frequency-response curve per sample.

    **Arguments:** `config`: a TOML file path, a TOML-shaped dict or a :class:`~hbgear.config.RunConfig`
    (with ``[study]``); `out`: output directory for ``study.csv``, ``study.json``, ``study.png``
    and the resumable record :data:`RECORD` (``None``: nothing written, nothing resumable);
    `overrides`: ``"section.key=value"`` strings applied to the base config first (as ``--set``);
    `resume`: continue an interrupted run of the same study in `out` (nothing recomputed); `fresh`:
    discard such a record and start again (without either, a record found in `out` is an error);
    `workers`: local processes (``None``: one per CPU; 1: this process); `scheduler`: a Dask
    scheduler address (default ``study.scheduler``); `progress`: a bar (``None``: on a terminal);
    `curves`: keep every sample's ``frc.csv`` columns (:meth:`StudyResult.curve`; with `out`,
    written as ``curves/sample-NNNN/frc.csv``; resumed samples recorded without one are computed again).

    **Returns:** a :class:`StudyResult`. **Raises:** :class:`~hbgear.errors.ConfigError` for a bad
    base config or ``[study]`` and for the record rule above; an interrupted run keeps its record.
    """
    from .build import check_config
    from .tasks import Journal, plan, run_tasks

    if resume and fresh:
        raise ConfigError("--fresh", True, "either --resume or --fresh, not both")
    started, t0 = datetime.now(timezone.utc).isoformat(timespec="seconds"), time.perf_counter()
    base, source = _base_document(config, overrides)
    parsed = parse_config(base)
    check_config(parsed)
    definition = parsed.study
    if not definition.parameters:
        raise ConfigError("study", "<missing>", 'a [study] section with [study.parameters] "section.key" = values')
    _check_targets(base, definition, parsed.to_dict())
    samples = draw_samples(definition)
    options = {"curves": bool(curves)}
    plain_base = sample_data(base, [])
    tasks = {i: (plain_base, _assignments(definition, s), options) for i, s in enumerate(samples)}
    fingerprint = _fingerprint(parsed, samples)
    journal, done = None, {}
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        journal = Journal(out / RECORD, fingerprint)
        done = _open_record(journal, resume, fresh)
        if curves:
            done = {k: r for k, r in done.items() if "curve" in r}
    address = scheduler if scheduler is not None else definition.scheduler
    mode, used = plan(workers, len(tasks) - len(done), address)
    results = run_tasks(run_sample, tasks, journal=journal, done=done, workers=workers, scheduler=address,
                        progress=progress, desc="study", unit="sample",
                        scheduler_key="--scheduler" if scheduler is not None else "study.scheduler")
    records = [results[i] | {"set": set_arguments(plain_base, tasks[i][1])} for i in range(len(samples))]
    info = {"timings_s": _timings(records, len(tasks) - len(done), time.perf_counter() - t0),
            "execution": {"mode": mode, "workers": used, "scheduler": address},
            "provenance": _provenance(source, overrides, fingerprint, started), "config_file": source,
            "config": parsed.to_dict()}
    result = StudyResult(definition.to_dict(), tuple(p.key for p in definition.parameters), samples, records, info)
    if out is not None:
        write_study(result, out)
        journal.remove()
    return result


# ----------------------------------------------------------------------------- files


def _json_record(record: dict) -> dict:
    return {k: v for k, v in record.items() if k != "curve"}


def write_study(result: StudyResult, out: str | os.PathLike) -> None:
    """``study.csv``, ``study.json``, ``study.png`` (and ``curves/sample-NNNN/frc.csv`` for kept
    curves) in `out`, each written atomically."""
    from .outputs.io import save_figure_atomic, write_csv_atomic, write_json_atomic

    out = Path(out)
    columns = result.columns
    write_csv_atomic(out / "study.csv", columns, ([row[c] for c in columns] for row in result.rows()))
    width = max(4, len(str(len(result) - 1)))
    for i, record in enumerate(result.records):
        if "curve" in record:
            folder = out / "curves" / f"sample-{i:0{width}d}"
            folder.mkdir(parents=True, exist_ok=True)
            curve = record["curve"]
            write_csv_atomic(folder / "frc.csv", list(curve), zip(*curve.values()))
    ok = int(result.success.sum())
    summary = {"command": "study", "kind": result.kind, "samples": len(result), "succeeded": ok,
               "failed": len(result) - ok, "parameters": list(result.keys), "columns": list(columns),
               "definition": result.definition,
               "records": [{"sample": i, **{k: s[k] for k in result.keys}, **_json_record(r)}
                           for i, (s, r) in enumerate(zip(result.samples, result.records))]}
    write_json_atomic(out / "study.json", summary | result.info)
    save_figure_atomic(result.plot(), out / "study.png", dpi=110)


def _number(text: str) -> Any:
    """A ``study.csv`` cell as the TOML value it spells (a number, list, ...), else the text."""
    import tomllib

    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def load_study(path: str | os.PathLike) -> StudyResult:
    """A study written by :func:`study` / ``hbgear study``, from its directory or its
    ``study.json`` / ``study.csv`` (``study.json`` when present: all records; else the
    ``study.csv`` rows, without the definition: the kind is taken as "grid").
    **Returns:** a :class:`StudyResult`."""
    import csv

    path = Path(path)
    folder = path if path.is_dir() else path.parent
    summary = folder / "study.json"
    if summary.exists():
        data = json.loads(summary.read_text(encoding="utf-8"))
        keys = tuple(data["parameters"])
        samples = [{k: r[k] for k in keys} for r in data["records"]]
        records = [{k: v for k, v in r.items() if k not in keys and k != "sample"} for r in data["records"]]
        info = {k: v for k, v in data.items() if k in ("timings_s", "execution", "provenance", "config_file", "config")}
        return StudyResult(data["definition"], keys, samples, records, info)
    table = folder / "study.csv"
    if not table.exists():
        raise FileNotFoundError(f"{folder}: no study.json or study.csv")
    with table.open(encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
        header = reader.fieldnames or []
    keys = tuple(header[1:header.index(METRICS[0])])
    samples = [{k: _number(row[k]) for k in keys} for row in rows]
    records = [{**{m: float(row[m]) for m in METRICS}, "success": row["success"] == "1", "status": row["status"],
                "message": row["message"]} for row in rows]
    for r in records:
        for m in METRICS[3:]:
            r[m] = int(r[m]) if math.isfinite(r[m]) else r[m]
    return StudyResult({"kind": "grid"}, keys, samples, records, {"config_file": None})
