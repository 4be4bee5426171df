"""Figures drawn into files by two processes: this one and a helper started with the command.

matplotlib draws in Python under the interpreter lock: the five figures of ``hbgear frc``
take ~1 s, a quarter of the LTV example's command, and a thread cannot share that work. A
:class:`FigureDrawer` created when a command starts launches one helper, a fresh interpreter
(``python -c``: never a fork of a process running JAX's threads, and no re-import of the
caller's script as :mod:`multiprocessing` would do), which imports matplotlib and the modules
the figures need while the computation runs. At :meth:`FigureDrawer.draw` the helper takes
figures from the front of the list and this process from the back, each figure whole, until
none is left: both cores draw. :meth:`~FigureDrawer.start` then :meth:`~FigureDrawer.finish`
is the same in two halves: the helper starts on the figures while this process writes its
tables, then this process draws what is left.

Every file is written by :func:`~hbgear.outputs.io.save_figure_atomic` in whichever process
draws it (never half-written). A figure that fails in the helper raises here, as it would have
in-process; a helper that died or could not start leaves its figures to this process. The
helper lives in a session of its own (Ctrl-C is this process's to handle) and ends when its
input closes: at :meth:`FigureDrawer.close` (which reaps it), or when this process ends in any way. On one usable
CPU, or with ``HBGEAR_FIGURE_PROCESS=0``, everything is drawn here.

**Public API:** :class:`FigureJob`, :class:`FigureDrawer`.
"""

from __future__ import annotations

import os
import pickle
import sys
import threading
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["FigureDrawer", "FigureJob", "HelperFailed"]

#: Modules the helper imports as soon as it starts (the figures' own are passed by the caller).
BASE_MODULES = ("numpy", "matplotlib.figure", "matplotlib.backends.backend_agg", "hbgear.outputs.plots",
                "hbgear.outputs.io")


@dataclass(frozen=True)
class FigureJob:
    """One figure: ``make(*args, **kwargs)`` returns a matplotlib ``Figure``, saved to `path` with
    the ``savefig`` keywords `savefig`. `make` and its arguments must pickle (a module-level
    function, or a bound method of a picklable object) for the helper to draw it."""

    make: Callable[..., Any]
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)
    path: Path = Path("figure.png")
    savefig: dict = field(default_factory=dict)

    def run(self) -> Path:
        from .io import save_figure_atomic

        return save_figure_atomic(self.make(*self.args, **self.kwargs), self.path, **self.savefig)


class HelperFailed(RuntimeError):
    """A figure failed in the helper with an exception that could not be sent back as itself."""


# ----------------------------------------------------------------------------- the helper's side


def _failure(exc: BaseException) -> bytes:
    """`exc` pickled, or a :class:`HelperFailed` with its text where it does not pickle."""
    try:
        return pickle.dumps(exc)
    except Exception:  # noqa: BLE001
        return pickle.dumps(HelperFailed(f"{type(exc).__name__}: {exc}"))


def _serve(modules: Sequence[str]) -> None:
    """The helper's loop (run by ``python -c``). Messages are pickles on stdin/stdout: it says
    ``"ready"`` once `modules` are imported; then it reads ``jobs`` (a pickled list), asks for
    work with ``("next", result)`` and draws the index it is given, until it is given ``None``;
    it ends at the end of its input, at once (``os._exit``: nothing is left to tear down)."""
    import importlib

    from ..runtime import pause_garbage_collection, resume_garbage_collection

    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr  # a stray print must not corrupt the channel
    pause_garbage_collection()  # the imports, as in the command's own process
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 -- the figure that needs it reports it
            pass
    resume_garbage_collection()
    try:
        _loop(stdin, stdout)
    except (EOFError, OSError):  # the command ended (or closed the pipes) first: nothing to say
        pass
    # Every figure it drew is a closed file; what is left is the interpreter's teardown of
    # matplotlib and JAX (~0.4 s that the command would wait for in :meth:`FigureDrawer.close`).
    sys.stderr.flush()
    os._exit(0)


def _loop(stdin, stdout) -> None:
    pickle.dump("ready", stdout)
    stdout.flush()
    while True:
        jobs = pickle.load(stdin)  # EOFError at the end of the input
        result = None
        while True:
            pickle.dump(("next", result), stdout)
            stdout.flush()
            index = pickle.load(stdin)
            if index is None:
                break
            try:
                result = (index, str(jobs[index].run()), None)
            except Exception as exc:  # noqa: BLE001 -- sent back, raised by the caller
                result = (index, None, _failure(exc))


# ----------------------------------------------------------------------------- the drawer


#: Seconds :meth:`FigureDrawer.close` waits for the helper to end before killing it (a helper
#: closed before it has finished importing: a command that failed early).
HELPER_EXIT_S = 5.0


class _Batch:
    """One :meth:`FigureDrawer.start`'s figures: which are left (`pending`), which the helper is
    drawing (`taken`), which it took and did not finish (`lost`: it died), the results."""

    def __init__(self, jobs):
        self.jobs = jobs
        self.pending = deque(range(len(jobs)))
        self.taken: set = set()
        self.lost: list = []
        self.paths: list = [None] * len(jobs)
        self.errors: dict = {}
        self.turn = threading.Condition()
        self.shared = False  # the helper has the list


class FigureDrawer:
    """Draws :class:`FigureJob` lists with a helper process (module docstring).

    **Arguments:** `modules`: imported by the helper when it starts (those the figures' objects
    need to unpickle, e.g. ``"hbgear.api"``); `helper`: ``None`` (default) uses one when two
    CPUs are usable and ``HBGEAR_FIGURE_PROCESS`` is not ``0``; ``False`` never; ``True``
    always. A context manager; or call :meth:`close`.

    **Attributes:** `drawn_by_helper`: figures of the last :meth:`draw` (or :meth:`start`) the helper drew.
    """

    def __init__(self, modules: Sequence[str] = (), *, helper: bool | None = None):
        if helper is None:
            from ..tasks import available_workers  # the CPUs this process may run on

            helper = os.environ.get("HBGEAR_FIGURE_PROCESS", "1").strip() != "0" and available_workers() >= 2
        self._process = None
        self._ready = False
        self._batch = None
        self.drawn_by_helper = 0
        if helper:
            self._process = self._start(tuple(BASE_MODULES) + tuple(modules))

    @staticmethod
    def _start(modules):
        import subprocess

        package_root = str(Path(__file__).resolve().parents[2])
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, env.get("PYTHONPATH")]))
        env["MPLBACKEND"] = "Agg"
        code = f"from hbgear.outputs.drawing import _serve; _serve({list(modules)!r})"
        try:
            return subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                    env=env, start_new_session=True)
        except OSError:
            return None

    @property
    def has_helper(self) -> bool:
        return self._process is not None

    def wait_ready(self, timeout_s: float) -> bool:
        """Wait at most `timeout_s` for the helper to finish its imports. **Returns:** whether it
        has (``False`` without a helper)."""
        import select

        process = self._process
        if process is None or self._ready:
            return self._ready and process is not None
        if not select.select([process.stdout], [], [], timeout_s)[0]:
            return False
        self._read_ready(process)
        return self._process is not None

    def _read_ready(self, process) -> None:
        try:
            if pickle.load(process.stdout) != "ready":
                raise EOFError
            self._ready = True
        except Exception:  # noqa: BLE001 -- a helper that cannot talk is no helper
            self._stop()

    def draw(self, jobs: Sequence[FigureJob]) -> list[Path]:
        """Draw every job (the helper from the front, this process from the back).

        **Returns:** the paths written, in the order of `jobs`. **Raises:** the exception of the
        first failing job (in the order of `jobs`), after every other job has finished."""
        self.start(jobs)
        return self.finish()

    def start(self, jobs: Sequence[FigureJob]) -> None:
        """Hand `jobs` to the helper, which starts on them from the front at once, and return:
        this process may do other work (write tables) before :meth:`finish` draws the rest."""
        if self._batch is not None:
            raise RuntimeError("FigureDrawer.start: the figures of the last start are not finished")
        jobs = list(jobs)
        self.drawn_by_helper = 0
        batch = _Batch(jobs)
        self._batch = batch
        if self._process is None or len(jobs) < 2:
            return
        try:
            blob = pickle.dumps(jobs, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 -- something does not pickle: draw here
            return
        batch.shared = True
        threading.Thread(target=self._feed, args=(batch, blob), name="hbgear-figures", daemon=True).start()

    def finish(self) -> list[Path]:
        """Draw what the helper has not taken (from the back), wait for what it took.

        **Returns**, **Raises:** as :meth:`draw`."""
        batch, self._batch = self._batch, None
        if batch is None:
            raise RuntimeError("FigureDrawer.finish without start")
        jobs, paths, errors, turn = batch.jobs, batch.paths, batch.errors, batch.turn
        if not batch.shared:
            for index in range(len(jobs)):
                self._run_here(jobs, index, paths, errors)
        while batch.shared:
            with turn:
                if not batch.pending:
                    break
                index = batch.pending.pop()
            self._run_here(jobs, index, paths, errors)
        with turn:
            turn.wait_for(lambda: not batch.taken)
        for index in batch.lost:
            self._run_here(jobs, index, paths, errors)
        if errors:
            raise errors[min(errors)]
        return paths

    def _feed(self, batch, blob) -> None:
        """The thread that talks to the helper; it is never waited for beyond the figures it took."""
        process, turn = self._process, batch.turn
        try:
            if not self._ready:
                if pickle.load(process.stdout) != "ready":
                    raise EOFError
                self._ready = True
            process.stdin.write(blob)
            process.stdin.flush()
            while True:
                _, result = pickle.load(process.stdout)
                with turn:
                    if result is not None:
                        index, path, error = result
                        if error is None:
                            batch.paths[index] = Path(path)
                            self.drawn_by_helper += 1
                        else:
                            batch.errors[index] = pickle.loads(error)
                        batch.taken.discard(index)
                    index = batch.pending.popleft() if batch.pending else None
                    if index is not None:
                        batch.taken.add(index)
                    turn.notify_all()
                pickle.dump(index, process.stdin)
                process.stdin.flush()
                if index is None:
                    return
        except Exception:  # noqa: BLE001 -- the helper is gone: what it took is drawn here
            with turn:
                batch.lost.extend(batch.taken)
                batch.taken.clear()
                turn.notify_all()
            self._stop()

    @staticmethod
    def _run_here(jobs, index, paths, errors) -> None:
        try:
            paths[index] = jobs[index].run()
        except Exception as exc:  # noqa: BLE001 -- raised by draw after the others finish
            errors[index] = exc

    def _stop(self) -> None:
        process, self._process = self._process, None
        if process is not None:
            for stream in (process.stdin, process.stdout):
                try:
                    stream.close()
                except OSError:
                    pass
            try:  # it exits at the end of its input (at once unless it is still importing)
                process.wait(timeout=HELPER_EXIT_S)
            except Exception:  # noqa: BLE001 -- still importing, or stuck: it has nothing to finish
                process.kill()
                process.wait()

    def close(self) -> None:
        """End the helper: its input closes and it exits (killed if it has not after
        :data:`HELPER_EXIT_S`)."""
        self._stop()

    def __enter__(self) -> FigureDrawer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
