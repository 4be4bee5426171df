"""Command-line framework: `hbgear <command> CONFIG [--set section.key=value ...] [--out DIR]`.

Commands live in a registry (:data:`COMMANDS`) filled through :func:`register`; the built-in
ones (`frc`, `solve`, `simulate`, `stability-map`, `static-te`, `validate`) are the modules of this package
(see :func:`_load_builtin_commands`).

Flow of :func:`main`: parse the arguments -> :func:`hbgear.config.load_config` with the
overrides -> :func:`hbgear.build.check_config` (the physics checks) -> the command's optional
`validate(config, args)` -> create the output directory (only now, so a bad input never leaves
anything behind) -> :func:`hbgear.runtime.configure` -> `run(config, args, out_dir)`. Everything
before `run` imports neither JAX nor matplotlib, so ``--help``, ``--version`` and every bad input
answer at once; command modules import their heavy dependencies inside `run`, and this module
imports the config, the physics checks and the outputs only once the arguments are parsed (the
front door, ``hbgear --help``, loads no numpy).

Exit status: 0 success (or what `run` returns); 2 bad input -- a
:class:`~hbgear.errors.ConfigError` or a usage error -- with exactly one line
`hbgear: error: <message>` on stderr; 1 a :class:`~hbgear.errors.ConvergenceError`
(`hbgear: did not converge: <message>`); 3 a :class:`CheckFailed` raised by a command after
writing its outputs (`hbgear validate`: HB and time integration disagree; `hbgear: validation
failed: <message>`); 130 interrupted (Ctrl-C).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import sys
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from ..errors import ConfigError, ConvergenceError

if TYPE_CHECKING:
    from ..config import RunConfig

__all__ = [
    "COMMANDS",
    "CheckFailed",
    "Command",
    "build_parser",
    "check_positive",
    "main",
    "positive_float",
    "positive_int",
    "register",
]

PROG = "hbgear"
EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT, EXIT_CHECK_FAILED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130


class CheckFailed(Exception):
    """A command's check did not hold (its outputs are written): exit 3, one stderr line."""


@dataclass(frozen=True)
class Command:
    """One subcommand.

    **Fields:**

    - `name`: the word typed after `hbgear`, e.g. ``"frc"``.
    - `help`: one-line description shown by ``hbgear --help``.
    - `add_arguments(parser)`: adds the command's own options (CONFIG, `--set` and `--out`
      are added by the framework). May be `None`.
    - `run(config, args, out_dir) -> int`: does the work and writes into `out_dir` (already
      created) through :mod:`hbgear.outputs.io`; returns the exit status (normally 0). Raise
      `ConfigError` for bad input and `ConvergenceError` for a failed computation.
    - `validate(config, args)`: optional check of the command's options against the
      config, run before the output directory is created; raise `ConfigError`.
    - `dynamic_model`: the command builds the dynamic model, so the config's physics checks
      (:func:`hbgear.build.check_config`) run first.
    """

    name: str
    help: str
    add_arguments: Callable[[argparse.ArgumentParser], None] | None
    run: Callable[[RunConfig, argparse.Namespace, Path], int]
    validate: Callable[[RunConfig, argparse.Namespace], None] | None = None
    dynamic_model: bool = True


COMMANDS: dict[str, Command] = {}


def register(command: Command, *, replace: bool = False) -> Command:
    """Add `command` to :data:`COMMANDS` (ValueError on a duplicate name unless `replace`).

    **Returns:** the command, so it can be used as ``FRC = register(Command(...))``.
    """
    if not isinstance(command, Command):
        raise TypeError(f"register() takes a Command, not {type(command).__name__}")
    if command.name in COMMANDS and COMMANDS[command.name] is not command and not replace:
        raise ValueError(f"a command named {command.name!r} is already registered")
    COMMANDS[command.name] = command
    return command


#: The shipped commands: one module each in this package, registering itself on import.
BUILTIN_COMMANDS = ("frc", "solve", "simulate", "stability_map", "static_te", "study", "validate")


def _load_builtin_commands() -> None:
    """Register the shipped commands (importing each module of :data:`BUILTIN_COMMANDS`)."""
    for name in BUILTIN_COMMANDS:
        importlib.import_module(f"{__name__}.{name}")


# ----------------------------------------------------------------------------- option types


def check_positive(option: str, value: object, allowed: str = "a positive finite number") -> float:
    """`value` as a finite float > 0, else `ConfigError(option, value, allowed)`."""
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(option, value, allowed) from None
    if isinstance(value, bool) or not math.isfinite(number) or number <= 0.0:
        raise ConfigError(option, value, allowed)
    return number


def positive_float(option: str, allowed: str = "a positive finite number"):
    """An argparse `type=` for a finite number > 0, e.g.
    ``parser.add_argument("--speed", type=positive_float("--speed", "a positive speed in rpm"))``.
    A bad value ends the run with exit 2 and one stderr line naming the option."""

    def convert(text: str) -> float:
        try:
            return check_positive(option, text, allowed)
        except ConfigError as exc:
            raise argparse.ArgumentTypeError(f"{text!r}: {exc.allowed}") from None

    convert.__name__ = "positive number"
    return convert


def positive_int(option: str, allowed: str = "a positive integer"):
    """An argparse `type=` for an integer >= 1 (e.g. ``--cycles``)."""

    def convert(text: str) -> int:
        try:
            number = int(text, 10)
        except ValueError:
            number = 0
        if number < 1:
            raise argparse.ArgumentTypeError(f"{text!r}: {allowed}")
        return number

    convert.__name__ = "positive integer"
    return convert


# ----------------------------------------------------------------------------- parser


class _UsageError(Exception):
    """argparse usage error, turned into exit 2 with one line by :func:`main`."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line (`hbgear: error: ...`), exit 2."""

    def error(self, message: str) -> NoReturn:
        raise _UsageError(f"{message} (see '{self.prog} --help')")


def _version() -> str:
    from importlib import metadata

    try:
        return metadata.version("hbgear")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser for all registered commands."""
    parser = _Parser(
        prog=PROG,
        description="Steady-state vibration of a spur-gear pair with tooth friction, by "
        "harmonic balance and time integration.",
        epilog="Exit status: 0 success, 1 did not converge, 2 bad input, 3 validation failed, 130 interrupted.",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for command in sorted(COMMANDS.values(), key=lambda c: c.name):
        p = sub.add_parser(command.name, help=command.help, description=command.help)
        p.add_argument("config", metavar="CONFIG", help="run configuration (TOML file)")
        p.add_argument(
            "--set",
            dest="overrides",
            action="append",
            default=None,
            metavar="SECTION.KEY=VALUE",
            help="override a config value (TOML syntax, repeatable), e.g. solver.harmonics=32",
        )
        p.add_argument(
            "--out",
            type=Path,
            default=None,
            metavar="DIR",
            help=f"output directory (default ./hbgear-out/{command.name})",
        )
        if command.add_arguments is not None:
            command.add_arguments(p)
    return parser


def _fail(prefix: str, message: object, status: int) -> int:
    text = " ".join(str(message).split()) or "(no message)"
    print(f"{PROG}: {prefix}: {text}", file=sys.stderr)
    return status


def main(argv: Sequence[str] | None = None, *, own_process: bool = False) -> int:
    """Run the CLI. **Returns:** the exit status (see the module docstring).

    `own_process`: the process is the command's (:func:`console_main`), which imported with the
    garbage collector paused (:func:`hbgear.runtime.pause_garbage_collection`); it is resumed,
    the imports frozen, once the runtime is configured."""
    argv = list(sys.argv[1:] if argv is None else argv)
    out_dir: Path | None = None
    created = False
    try:
        _load_builtin_commands()
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help / --version
            return exc.code if isinstance(exc.code, int) else EXIT_OK
        if args.command is None:
            parser.print_help(sys.stderr)
            return EXIT_BAD_INPUT
        command = COMMANDS[args.command]
        from .. import runtime
        from ..build import check_config
        from ..config import load_config
        from ..outputs.io import prepare_out_dir

        config = load_config(args.config, args.overrides or ())
        if command.dynamic_model:
            check_config(config)
        if command.validate is not None:
            command.validate(config, args)
        out_dir = args.out if args.out is not None else Path("hbgear-out") / command.name
        created = not out_dir.exists()
        out_dir = prepare_out_dir(out_dir)
        with warnings.catch_warnings(record=True) as said:  # e.g. a jax too old for the disk cache
            warnings.simplefilter("always")
            runtime.configure()  # one XLA thread, the disk compilation cache: before any computation
        if own_process:
            runtime.resume_garbage_collection()
        for warning in said:
            print(f"hbgear: warning: {warning.message}", file=sys.stderr)
        status = command.run(config, args, out_dir)
        return EXIT_OK if status is None else int(status)
    except _UsageError as exc:
        return _fail("error", exc, EXIT_BAD_INPUT)
    except ConfigError as exc:
        _remove_if_empty(out_dir, created)
        return _fail("error", exc, EXIT_BAD_INPUT)
    except ConvergenceError as exc:
        _remove_if_empty(out_dir, created)
        return _fail("did not converge", exc, EXIT_NOT_CONVERGED)
    except CheckFailed as exc:
        return _fail("validation failed", exc, EXIT_CHECK_FAILED)
    except KeyboardInterrupt:
        _remove_if_empty(out_dir, created)
        return _fail("interrupted", "stopped by the user (no partial files written)", 130)


def console_main() -> NoReturn:
    """The ``hbgear`` console script and ``python -m hbgear``: :func:`main`, then the process ends
    at once with its status. Every output file is complete and closed when :func:`main` returns
    (written atomically), so nothing is left for the interpreter's shutdown but tearing down
    JAX's runtime and the imported modules: 0.3-0.4 s of the LTV example's ~5 s, skipped here
    (``os._exit`` after flushing the standard streams and the logging handlers). :func:`main`
    itself returns, for callers in Python. The process ends normally (its ``atexit`` handlers
    run) under a profiler or tracer (``python -m cProfile -m hbgear``, pyinstrument, coverage),
    which write their reports at exit, and with ``HBGEAR_FAST_EXIT=0``. The imports run with the
    garbage collector paused (:func:`hbgear.runtime.pause_garbage_collection`) and OpenBLAS
    makes no threads (:func:`hbgear.runtime.blas_without_threads`)."""
    import os

    from ..runtime import blas_without_threads, pause_garbage_collection

    pause_garbage_collection()
    blas_without_threads()
    status = main(own_process=True)
    if (sys.getprofile() is not None or sys.gettrace() is not None
            or os.environ.get("HBGEAR_FAST_EXIT", "1").strip() == "0"):
        sys.exit(status)
    jax = sys.modules.get("jax")
    if jax is not None:
        with contextlib.suppress(Exception):
            jax.effects_barrier()  # nothing in flight that a callback would still print
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


def _remove_if_empty(out_dir: Path | None, created: bool) -> None:
    """Leave no empty output directory behind after a failed run that created it."""
    if out_dir is not None and created:
        with contextlib.suppress(OSError):
            out_dir.rmdir()  # only succeeds if empty


if __name__ == "__main__":  # pragma: no cover
    console_main()
