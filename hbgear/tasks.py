"""Independent tasks, run in this process, in local worker processes or on a Dask cluster, with a
progress bar and a resumable record of the finished ones (``hbgear study``, ``hbgear stability-map``).

- :func:`run_tasks` computes ``fn(*args)`` for every task not finished already and returns every
  result by task key, in the order of the tasks. One worker: in this process, one task after the
  other. More: a :class:`concurrent.futures.ProcessPoolExecutor` of freshly spawned processes, each
  with the one-thread XLA runtime and the disk compilation cache of :func:`hbgear.runtime.configure`
  (a worker reuses what it compiled for its earlier tasks; the processes share the disk cache).
  A scheduler address: Dask futures on that cluster (``dask.distributed``, the ``distributed``
  extra); a worker process configures its runtime before its first task.
- :class:`Journal`: the record. An append-only text file whose first line is a
  :func:`fingerprint` of what is computed (a record of another definition is never resumed),
  then the codec's header line if it has one, then the finished tasks; each is written with one
  ``write``, flushed and fsynced as soon as its result arrives, so a killed run loses only the
  tasks that were running. Opening it rewrites the valid part atomically, so a record cut by a
  crash never glues onto the next one. :class:`JsonLines` (one JSON object per task) is the
  default codec; a caller may keep its own file format with its own codec.
- :class:`CompileClock`: the seconds this process spends compiling while a block runs.

Interrupting (Ctrl-C, an exception in a task) cancels the tasks not started, stops the worker
processes and keeps the record of what finished.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import threading
import time
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from .errors import ConfigError
from .outputs.io import write_text_atomic

__all__ = ["CompileClock", "Journal", "JsonLines", "available_workers", "fingerprint", "plan", "run_tasks"]


def fingerprint(kind: str, data: Any) -> str:
    """The first line of a record: ``# hbgear <kind> partial; sha256=<hash of data as sorted JSON>``."""
    text = json.dumps(data, sort_keys=True, default=str)
    return f"# hbgear {kind} partial; sha256=" + hashlib.sha256(text.encode()).hexdigest()


# ----------------------------------------------------------------------------- the record


class JsonLines:
    """Record codec: one line ``{"task": key, "result": result}`` per finished task (JSON keys and
    results; floats round-trip exactly, NaN allowed). A line that does not parse -- the one a crash
    cut -- is skipped."""

    header: str | None = None

    def encode(self, key: Hashable, result: Any) -> str:
        return json.dumps({"task": key, "result": result}, separators=(",", ":")) + "\n"

    def decode(self, lines: Iterable[str]) -> dict:
        done = {}
        for line in lines:
            try:
                record = json.loads(line)
            except ValueError:
                continue
            if isinstance(record, dict) and set(record) == {"task", "result"}:
                done[record["task"]] = record["result"]
        return done


class Journal:
    """The resumable record of finished tasks at `path` (see the module docstring).

    **Arguments:** `path`; `fingerprint` (the first line, :func:`fingerprint`); `codec` (an object
    with ``header`` (a line or ``None``), ``encode(key, result) -> text`` and
    ``decode(lines) -> {key: result}``; default :class:`JsonLines`).
    """

    def __init__(self, path: str | os.PathLike, fingerprint: str, codec=None):
        self.path, self.fingerprint = Path(path), fingerprint
        self.codec = JsonLines() if codec is None else codec
        self._fh = None

    def _head(self) -> list[str]:
        return [self.fingerprint] + ([] if self.codec.header is None else [self.codec.header])

    def _lines(self) -> list[str] | None:
        try:
            return self.path.read_text(encoding="utf-8").splitlines()
        except FileNotFoundError:
            return None
        except (OSError, UnicodeDecodeError):
            return []

    def state(self) -> str:
        """``"absent"`` (no record), ``"same"`` (a record of this fingerprint) or ``"other"``."""
        lines = self._lines()
        if not lines:
            return "absent" if lines is None or not self.path.exists() else "other"
        head = self._head()
        return "same" if lines[:len(head)] == head else "other"

    def read(self) -> dict:
        """The finished tasks of a record with this fingerprint (``{}`` if there is none)."""
        if self.state() != "same":
            return {}
        return self.codec.decode(self._lines()[len(self._head()):])

    def start(self, done: Mapping) -> None:
        """(Re)write the record with `done` atomically, then keep it open for appending."""
        text = "".join(line + "\n" for line in self._head())
        text += "".join(self.codec.encode(key, result) for key, result in done.items())
        write_text_atomic(self.path, text)
        self._fh = open(self.path, "a", encoding="utf-8", newline="")

    def add(self, key: Hashable, result: Any) -> None:
        """Append one finished task, flushed and fsynced."""
        self._fh.write(self.codec.encode(key, result))
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def remove(self) -> None:
        self.close()
        self.path.unlink(missing_ok=True)


# ----------------------------------------------------------------------------- compile time

_COMPILE_EVENTS = frozenset({"/jax/core/compile/jaxpr_trace_duration",
                             "/jax/core/compile/jaxpr_to_mlir_module_duration",
                             "/jax/core/compile/backend_compile_duration"})
_SPANS: list[tuple[float, float]] = []
_CLOCKS = [0]  # clocks running in this process
_LOCK = threading.Lock()
_LISTENING = [False]


def _on_span(event: str, start: float, end: float, **_) -> None:
    if event in _COMPILE_EVENTS and _CLOCKS[0]:
        with _LOCK:
            _SPANS.append((start, end))


def _union_seconds(spans: list[tuple[float, float]]) -> float:
    """Length of the union of the intervals (nested tracing is counted once)."""
    total, reach = 0.0, -float("inf")
    for start, end in sorted(spans):
        if end > reach:
            total += end - max(start, reach)
            reach = end
    return total


class CompileClock:
    """``with CompileClock() as clock: ...`` then ``clock.seconds``: the time this process spent
    compiling in the block -- JAX's tracing, lowering and XLA compilation or disk-cache load,
    the union of the time spans of its compile events (other threads' compilations included)."""

    seconds: float = 0.0

    def __enter__(self) -> CompileClock:
        import jax.monitoring

        with _LOCK:
            if not _LISTENING[0]:
                jax.monitoring.register_event_time_span_listener(_on_span)
                _LISTENING[0] = True
            _CLOCKS[0] += 1
            self._first, self._t0 = len(_SPANS), time.time()
        return self

    def __exit__(self, *exc) -> None:
        with _LOCK:
            self.seconds = _union_seconds([s for s in _SPANS[self._first:] if s[0] >= self._t0])
            _CLOCKS[0] -= 1
            if not _CLOCKS[0]:
                _SPANS.clear()


# ----------------------------------------------------------------------------- running


def available_workers() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _watch_parent(parent: int) -> None:
    """End this worker when the process that started it is gone (e.g. killed with SIGKILL)."""
    while os.getppid() == parent:
        time.sleep(1.0)
    os._exit(1)


def _init_worker(parent: int) -> None:
    """A local worker process: Ctrl-C is the parent's to handle; the one-thread runtime and cache."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()
    from . import runtime

    runtime.configure()
    _CONFIGURED[0] = True


_CONFIGURED = [False]


def _on_worker(fn: Callable, args: tuple, driver: int) -> Any:
    """A task on a Dask worker: a worker process of its own configures its runtime first."""
    with _LOCK:
        if not _CONFIGURED[0] and os.getpid() != driver:
            from . import runtime

            runtime.configure()
        _CONFIGURED[0] = True
    return fn(*args)


def _serial(fn, todo):
    for key, args in todo.items():
        yield key, fn(*args)


def _stop_pool(pool, futures) -> None:
    for future in futures:
        future.cancel()
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            process.terminate()
    pool.shutdown(wait=False, cancel_futures=True)


def _processes(fn, todo, workers: int):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_init_worker, initargs=(os.getpid(),))
    futures = {}
    try:
        futures = {pool.submit(fn, *args): key for key, args in todo.items()}
        for future in as_completed(futures):
            yield futures[future], future.result()
    except BrokenProcessPool as error:
        _stop_pool(pool, futures)
        raise RuntimeError("a local worker process died (killed, out of memory, or it could not start: a script "
                           "that runs tasks in worker processes needs the `if __name__ == \"__main__\":` guard); "
                           "the tasks finished before it are kept in the record") from error
    except BaseException:
        _stop_pool(pool, futures)
        raise
    pool.shutdown(wait=True)


def _connect(address: str, key: str):
    try:
        from dask.distributed import Client
    except ImportError:
        raise ConfigError(key, address,
                          "a Dask scheduler needs dask.distributed: install hbgear[distributed]") from None
    try:
        return Client(address)
    except OSError as error:  # refused, unreachable, timed out
        raise ConfigError(key, address, f"a reachable Dask scheduler ({type(error).__name__}: {error})") from None


def _dask(fn, todo, address: str, key: str):
    client = _connect(address, key)
    futures = {}
    try:
        from dask.distributed import as_completed

        futures = {client.submit(_on_worker, fn, args, os.getpid(), pure=False): k for k, args in todo.items()}
        for future in as_completed(futures):
            yield futures[future], future.result()
    except BaseException:
        client.cancel(list(futures))
        raise
    finally:
        client.close()


def plan(workers: int | None, tasks: int, scheduler: str | None = None) -> tuple[str, int]:
    """How :func:`run_tasks` runs `tasks` tasks: ``("dask", 0)``, ``("processes", n)`` or
    ``("in-process", 1)`` (`workers` ``None``: one per CPU; never more processes than tasks)."""
    if scheduler is not None:
        return "dask", 0
    n = min(available_workers() if workers is None else int(workers), tasks)
    return ("processes", n) if n > 1 else ("in-process", 1)


def _results(fn, todo: dict, workers: int | None, scheduler: str | None, scheduler_key: str) -> Iterator:
    mode, n = plan(workers, len(todo), scheduler)
    if mode == "dask" and todo:
        return _dask(fn, todo, scheduler, scheduler_key)
    if mode == "processes":
        return _processes(fn, todo, n)
    return _serial(fn, todo)


def run_tasks(fn: Callable, tasks: Mapping[Hashable, tuple], *, journal: Journal | None = None,
              done: Mapping | None = None, workers: int | None = 1, scheduler: str | None = None,
              progress: bool | None = True, desc: str | None = None, unit: str = "task",
              scheduler_key: str = "--scheduler", on_result: Callable | None = None) -> dict:
    """``fn(*tasks[key])`` for every key not in `done`, then every result by key in task order.

    **Arguments:** `fn` (a module-level function when it runs in other processes); `tasks`
    ``{key: args}``; `journal`: record of the finished tasks, (re)started with `done` and appended
    to as results arrive; `done` ``{key: result}`` finished already (keys not in `tasks` are
    dropped); `workers`: local processes (``None``: one per available CPU; at most one per task to
    run; 1: in this process); `scheduler`: a Dask scheduler address (then `workers` is ignored);
    `progress`: a tqdm bar on a terminal (``False``: none); `desc`, `unit`: its labels; `scheduler_key`: the
    option named when Dask is missing; `on_result(key, result)`: called as each result arrives.

    **Returns:** ``{key: result}`` for every task. **Raises:** what a task raised (the record keeps
    the tasks finished before), :class:`~hbgear.errors.ConfigError` when Dask is missing.
    """
    from tqdm import tqdm

    done = {k: v for k, v in (done or {}).items() if k in tasks}
    todo = {k: tasks[k] for k in tasks if k not in done}
    if journal is not None:
        journal.start(done)
    bar = tqdm(total=len(tasks), initial=len(done), desc=desc, unit=unit, disable=True if progress is False else None)
    try:
        with contextlib.closing(_results(fn, todo, workers, scheduler, scheduler_key)) as results:
            for key, result in results:
                done[key] = result
                if journal is not None:
                    journal.add(key, result)
                if on_result is not None:
                    on_result(key, result)
                bar.update(1)
    finally:
        bar.close()
        if journal is not None:
            journal.close()
    return {k: done[k] for k in tasks}
