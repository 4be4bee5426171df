"""Opt-in process settings that make hbgear fast: one XLA thread, one BLAS thread, a disk cache,
freed memory kept.

``import hbgear`` changes none of these; the ``hbgear`` command calls :func:`configure` before it
computes anything, and a library user may call it too (before JAX creates its CPU client, i.e.
before the first JAX computation of the process, for the thread setting to take effect)::

    import hbgear
    hbgear.runtime.configure()  # one XLA and one BLAS thread, XLA's LLVM emitters, the disk cache, glibc's thresholds

- **One XLA thread.** A continuation step is ~340 small kernels; XLA:CPU hands independent ones
  to an intra-op pool of one thread per CPU, and on small kernels the hand-offs cost more than
  they win (2 cores: a point of the NLTV curve 1.0-1.3 ms with the pool, 0.7 ms with one
  thread). JAX sizes that pool from the process's CPU affinity when it creates its CPU client,
  so the client is created under a one-CPU affinity, which is then restored for every thread
  (compilation keeps all cores: its threads are made later). Linux only.
- **One BLAS thread.** The dense LU and eigen-decompositions (JAX's CPU LAPACK calls go to the
  same OpenBLAS as SciPy's) are of a few hundred unknowns; OpenBLAS threads them from ~300 and
  on a 2-core machine with anything else running the threads wait for each other: an LU of 391
  unknowns took 196 ms (median of 20; minimum 14 ms) with the default threads, 3.7 ms with one;
  a continuation point of the NLTV pair on bearings and shafts (8 DOF) cost 62x the 2-DOF point
  with the default threads, 7x with one (``benchmarks/bench_bearings.py``). Hill's method limits
  BLAS to one thread around its eigenproblems anyway. The ``hbgear`` command goes further
  (:func:`blas_without_threads`): ``OPENBLAS_NUM_THREADS=1`` before NumPy loads, so OpenBLAS
  makes no worker thread at all (each library's thread otherwise spins ~0.1 s of CPU when
  it loads: four such spins, NumPy's and SciPy's in the command and in its figure helper,
  took ~0.3 s of the two cores while the LTV example started).
- **XLA:CPU's LLVM IR emitters** (:func:`fast_compilation`): ``--xla_cpu_use_fusion_emitters=false``
  in ``XLA_FLAGS`` before JAX creates its CPU client. XLA's newer emitters lower every fusion
  through an MLIR pipeline of its own, which is most of the compile time of hbgear's programs
  (many small fusions): the LTV example's corrector compiled in 1.17 s instead of 1.95 s, the
  NLTV command's three programs in 2.79 s instead of 4.29 s, two test files ran in 76 s instead
  of 129 s. The programs run as fast within the noise at H = 32 and H = 512 (the continuation
  of ``examples/low_speed_nltv.toml``), ~7 % slower at H = 256 (three pairs), 2026-12-04.
- **Disk compilation cache** (``~/.cache/hbgear/jax``, or ``$HBGEAR_CACHE_DIR``): a second run
  of the same problem structure starts without compiling; and, in its folder ``hbgear-programs``,
  the traced programs of hbgear's own functions (:mod:`hbgear.engine.persistent`), so that it
  starts without tracing them either (the LTV example 0.35 s sooner, the NLTV curve 0.9 s).
- **Freed memory kept for reuse** (glibc): blocks above 128 kB are otherwise ``mmap``-ed and
  returned to the system when freed, and every reuse page-faults afresh: on this project's VMs
  ``a0 + mu a1 + mu**2 a2`` of 130 x 130 matrices (Hill's pencil, four such temporaries) took
  0.53-0.73 ms, 0.05-0.07 ms with the memory kept; Hill's method on the NLTV curve 12-15 %
  less (three alternated pairs). The ``mmap`` threshold is raised to 64 MB and the trim
  threshold to 512 MB (``mallopt``), so such blocks come from the heap and stay mapped. Linux
  with glibc only.

The ``hbgear`` command also imports without Python's cyclic garbage collector
(:func:`pause_garbage_collection`) and freezes what the imports made before it computes
(:func:`resume_garbage_collection`): the collector's full passes over the growing heap of an
import (three of 24-90 ms in the LTV example) cost ~0.2 s a command, the passes after the
freeze ~0.05 s. A library user's process is left alone.

Environment: ``HBGEAR_XLA_EMITTERS=default`` keeps XLA's emitters; ``HBGEAR_RUNTIME_THREADS=default``
keeps JAX's pool; ``HBGEAR_BLAS_THREADS=default`` keeps OpenBLAS's threads; ``HBGEAR_NO_CACHE=1``
leaves the cache off; ``HBGEAR_MALLOC=default`` keeps glibc's thresholds.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

__all__ = ["configure", "enable_compilation_cache", "pause_garbage_collection", "resume_garbage_collection",
           "blas_without_threads", "fast_compilation", "single_threaded_runtime", "single_thread_blas_runtime",
           "keep_freed_memory", "default_cache_dir"]


#: The folder of the cache directory where traced programs are kept (:mod:`hbgear.engine.persistent`).
PROGRAMS_SUBDIR = "hbgear-programs"


def default_cache_dir() -> Path:
    """``$HBGEAR_CACHE_DIR``, else ``$XDG_CACHE_HOME/hbgear/jax`` (``~/.cache/hbgear/jax``)."""
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "hbgear" / "jax"
    return Path(os.environ.get("HBGEAR_CACHE_DIR", default))


#: The first JAX release whose programs loaded from the disk cache compute what they computed when
#: compiled: with jax/jaxlib 0.5.3 a ``while_loop`` around a matrix product, loaded from the cache,
#: returned its initial state (the compiled continuation corrector gave zero tangents and a curve
#: that never ended); 0.6.2 and later were checked.
CACHE_SAFE_JAX = (0, 6, 2)


def _release(version: str) -> tuple[int, ...]:
    """``"0.10.2"`` -> ``(0, 10, 2)``; the first three numbers of a version string."""
    return tuple(int(number) for number in re.findall(r"\d+", version)[:3])


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Keep compiled XLA programs on disk across runs; **returns** the directory, or ``None`` when
    ``HBGEAR_NO_CACHE`` is set, the directory cannot be created, or the installed JAX is older than
    :data:`CACHE_SAFE_JAX` (a warning then says so)."""
    if os.environ.get("HBGEAR_NO_CACHE"):
        return None
    import jax

    if _release(jax.__version__) < CACHE_SAFE_JAX:
        warnings.warn(f"jax {jax.__version__}: the disk compilation cache stays off (programs loaded from it "
                      f"can return wrong results before jax {'.'.join(map(str, CACHE_SAFE_JAX))}; upgrade jax)",
                      RuntimeWarning, stacklevel=2)
        return None
    directory = Path(path) if path is not None else default_cache_dir()
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    return directory


#: The flag :func:`fast_compilation` adds to ``XLA_FLAGS`` (the module docstring).
FAST_COMPILATION_XLA_FLAG = "--xla_cpu_use_fusion_emitters=false"


def _declined(variable: str) -> bool:
    """Whether the environment variable `variable` is ``default``: the user keeps the library's own setting."""
    return os.environ.get(variable, "").strip().lower() == "default"


def _backend_exists() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge.backends_are_initialized())
    except Exception:  # pragma: no cover - a JAX without this hook: assume it may exist
        return True


def fast_compilation() -> bool:
    """Add :data:`FAST_COMPILATION_XLA_FLAG` to ``XLA_FLAGS`` (XLA reads it when JAX creates its
    CPU client). **Returns:** whether it was done: ``False`` with ``HBGEAR_XLA_EMITTERS=default``,
    when ``XLA_FLAGS`` names the emitters already (the user's choice), or when JAX's backend
    exists already (JAX used before: too late for this process)."""
    if _declined("HBGEAR_XLA_EMITTERS"):
        return False
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_use_fusion_emitters" in flags or _backend_exists():
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FAST_COMPILATION_XLA_FLAG}".strip()
    return True


def _threads() -> set[str]:
    try:
        return set(os.listdir("/proc/self/task"))
    except OSError:  # pragma: no cover
        return set()


def single_threaded_runtime() -> bool:
    """Create JAX's CPU client with a one-thread intra-op pool (see the module docstring).

    **Returns:** whether it was done: ``False`` when ``HBGEAR_RUNTIME_THREADS=default``, on a
    one-CPU process, off Linux, or when JAX's backend exists already (JAX used before). An
    unknown ``HBGEAR_RUNTIME_THREADS`` value warns once and keeps the one-thread runtime.
    """
    setting = os.environ.get("HBGEAR_RUNTIME_THREADS", "1").strip().lower()
    if setting not in ("1", "default"):
        warnings.warn(f"HBGEAR_RUNTIME_THREADS = {setting!r}: expected '1' or 'default'; using '1'",
                      RuntimeWarning, stacklevel=2)
    if setting == "default" or not hasattr(os, "sched_setaffinity"):
        return False
    import jax

    if _backend_exists():  # JAX used before (or a JAX without the hook: keep its default)
        return False
    original = os.sched_getaffinity(0)
    if len(original) < 2:
        return False
    before = _threads()
    try:
        os.sched_setaffinity(0, {min(original)})
        jax.devices()
    except Exception:  # pragma: no cover - no usable backend: JAX reports it at first use
        pass
    finally:
        for tid in [0, *(int(t) for t in _threads() - before)]:
            try:
                os.sched_setaffinity(tid, original)
            except OSError:  # pragma: no cover - the thread has ended, or the mask is refused
                pass
    return True


_BLAS_LIMIT: list = []


def blas_without_threads() -> bool:
    """Set ``OPENBLAS_NUM_THREADS=1`` for this process and its children, before NumPy or SciPy
    load OpenBLAS (later it changes nothing). For a process that is the command's own: a library
    user's environment is left alone. **Returns:** whether it was set: not with
    ``HBGEAR_BLAS_THREADS=default`` nor when ``OPENBLAS_NUM_THREADS`` is set already."""
    if _declined("HBGEAR_BLAS_THREADS") or "OPENBLAS_NUM_THREADS" in os.environ:
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True


def single_thread_blas_runtime() -> bool:
    """Limit the process's BLAS/LAPACK libraries (NumPy's and SciPy's OpenBLAS, which JAX's CPU
    LAPACK calls use too) to one thread for the rest of the process (see the module docstring).
    **Returns:** whether it was done: ``False`` with ``HBGEAR_BLAS_THREADS=default``."""
    if _declined("HBGEAR_BLAS_THREADS"):
        return False
    if not _BLAS_LIMIT:
        import scipy.linalg  # noqa: F401 -- loads SciPy's BLAS so that the limit reaches it
        from threadpoolctl import ThreadpoolController

        _BLAS_LIMIT.append(ThreadpoolController().limit(limits=1, user_api="blas"))  # kept: never restored
    return True


#: ``mallopt`` parameters of glibc (malloc.h) and the values :func:`keep_freed_memory` sets.
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD_BYTES, TRIM_THRESHOLD_BYTES = 64 << 20, 512 << 20


def keep_freed_memory() -> bool:
    """Raise glibc's ``mmap`` and trim thresholds (see the module docstring). **Returns:** whether
    it was done: ``False`` with ``HBGEAR_MALLOC=default`` or without glibc's ``mallopt``."""
    if _declined("HBGEAR_MALLOC"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # pragma: no cover - not glibc
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(mallopt(_M_TRIM_THRESHOLD,
                                                                                   TRIM_THRESHOLD_BYTES))


def pause_garbage_collection() -> None:
    """Switch off Python's cyclic garbage collector while a command imports its libraries (the
    module docstring). For a process that is the command's own: :func:`resume_garbage_collection`
    must follow before it computes."""
    import gc

    gc.disable()


def resume_garbage_collection() -> None:
    """Freeze every object alive now (``gc.freeze``: the imported modules, their functions and
    classes, which live as long as the process; the collector never scans them again) and
    switch the collector back on for what the computation makes."""
    import gc

    gc.freeze()
    gc.enable()


def configure(*, threads: bool = True, cache: bool = True, memory: bool = True, compilation: bool = True) -> dict:
    """The settings (each optional); **returns** what was done, e.g. ``{"single_thread": True,
    "cache_dir": "/home/u/.cache/hbgear/jax", "keep_freed_memory": True, "fast_compilation": True}``."""
    done = {}
    if compilation:  # before the thread setting, which creates JAX's CPU client
        done["fast_compilation"] = fast_compilation()
    if cache:
        directory = enable_compilation_cache()
        done["cache_dir"] = None if directory is None else str(directory)
        if directory is not None:  # traced programs beside the compiled ones (hbgear.engine.persistent)
            from .engine import persistent

            done["programs_dir"] = str(persistent.enable(directory / PROGRAMS_SUBDIR))
    if threads:
        done["single_thread"] = single_threaded_runtime()
        done["single_thread_blas"] = single_thread_blas_runtime()
    if memory:
        done["keep_freed_memory"] = keep_freed_memory()
    return done
