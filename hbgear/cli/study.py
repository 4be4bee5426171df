"""``hbgear study CONFIG``: one frequency-response curve per sample of ``[study]`` (:func:`hbgear.study`).

Each sample is the base config with the sample's overrides, checked by the normal loader, and
its curve is exactly the one ``hbgear frc`` computes with the same ``--set`` values (recorded per
sample in ``study.json``). Writes into the output directory:

- ``study.csv``: one row per sample -- ``sample``, the varied keys (named as in
  ``[study.parameters]``), then :data:`hbgear.studies.RESULT_COLUMNS` (``peak_dte_p2p_um,
  peak_speed_rpm, max_dynamic_factor, unstable_zones, success`` (1/0), ``unstable_points, folds,
  period_doublings, points, status, message``); no timings, so a resumed study's file is
  byte-identical to an uninterrupted one;
- ``study.json``: the definition, every sample's record (zones, period doublings, folds, the
  ``--set`` arguments, seconds, compile seconds, worker), timings (samples per minute, the
  fraction of the time spent compiling), execution and provenance, the config;
- ``study.png``: the picture (:meth:`hbgear.studies.StudyResult.plot`);
- with ``--curves``: ``curves/sample-NNNN/frc.csv`` per sample.

Runs on local processes (one per CPU, ``--workers N``; 1 = in this process) or, with
``study.scheduler`` / ``--scheduler ADDRESS``, on a Dask cluster. Every finished sample is
appended to ``study.partial.jsonl`` (fsynced); ``--resume`` continues an interrupted study
without recomputing a sample, ``--fresh`` discards the record; without either, a record found in
the output directory is refused (exit 2), so nothing is lost by a mistyped command. The record
is removed once the outputs are written.

Exit status: 0 when every sample ran (failed samples -- ``success = 0`` -- are reported on
stderr), 1 when no sample succeeded, 2 bad input, 130 interrupted (the record is kept).
"""

from __future__ import annotations

import sys

from . import Command, positive_int, register
from ..errors import ConfigError

__all__ = ["STUDY"]


def _add_arguments(parser) -> None:
    again = parser.add_mutually_exclusive_group()
    again.add_argument("--resume", action="store_true", help="continue an interrupted study in the output directory")
    again.add_argument("--fresh", action="store_true", help="discard an interrupted study's record and start again")
    parser.add_argument("--scheduler", default=None, metavar="ADDRESS",
                        help="Dask scheduler address (e.g. tcp://host:8786); overrides study.scheduler")
    parser.add_argument("--workers", type=positive_int("--workers"), default=None, metavar="N",
                        help="local worker processes (default: one per CPU; 1 = in this process)")
    parser.add_argument("--curves", action="store_true", help="also write every sample's curves/sample-NNNN/frc.csv")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (default: only on a terminal)")


def _scheduler(config, args) -> tuple[str | None, str]:
    if args.scheduler is not None:
        return args.scheduler, "--scheduler"
    return config.study.scheduler, "study.scheduler"


def _validate(config, args) -> None:
    if not config.study.parameters:
        raise ConfigError("study", "<missing>", 'a [study] section with [study.parameters] "section.key" = values')
    address, key = _scheduler(config, args)
    if address is not None:
        if not address.strip():
            raise ConfigError(key, address, 'a Dask scheduler address such as "tcp://host:8786"')
        try:
            import dask.distributed  # noqa: F401
        except ImportError:
            raise ConfigError(key, address,
                              "a Dask scheduler needs dask.distributed: install hbgear[distributed]") from None


def _report(result, out_dir) -> int:
    ok = int(result.success.sum())
    t = result.info["timings_s"]
    print(f"study: {len(result)} samples ({result.kind}), {ok} succeeded; {t['samples_computed']} computed, "
          f"{t['samples_resumed']} resumed, {t['wall']:.1f} s ({t['samples_per_minute']:.3g} samples/min, "
          f"{100 * t['compile_fraction']:.0f}% compiling) -> {out_dir}")
    failed = [(i, r) for i, r in enumerate(result.records) if not r["success"]]
    if failed:
        i, r = failed[0]
        print(f"hbgear: warning: {len(failed)} of {len(result)} samples failed (success = 0 in study.csv); "
              f"first: sample {i}: {r['message']}", file=sys.stderr)
    return 1 if failed and not ok else 0


def _run(config, args, out_dir) -> int:
    from ..studies import RECORD, study

    try:
        result = study(args.config, out=out_dir, overrides=args.overrides or (), resume=args.resume, fresh=args.fresh,
                       workers=args.workers, scheduler=args.scheduler, progress=False if args.no_progress else None,
                       curves=args.curves)
    except KeyboardInterrupt:
        print(f"hbgear: interrupted: the finished samples are kept in {out_dir / RECORD}; continue with --resume",
              file=sys.stderr)
        return 130
    return _report(result, out_dir)


STUDY = register(Command(name="study", help="one frequency-response curve per sample of [study] (grid or Monte Carlo) "
                         "-> study.csv/.json/.png; local processes or Dask; --resume", add_arguments=_add_arguments,
                         run=_run, validate=_validate))
