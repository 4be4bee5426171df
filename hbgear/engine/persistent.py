r"""Traced programs kept on disk, so that a warm run does not trace them again.

JAX's disk cache keeps *compiled* programs, but finds one only from the lowered program, so every
process traces and lowers its functions first: for the continuation corrector (``advance``) of the
gear pair 0.45-0.8 s of a 4-5 s command. :func:`persistent` wraps a function so that its traced and
lowered form is exported once (``jax.export``, StableHLO) into :func:`enable`\ 's directory and
later processes deserialise it (milliseconds) instead; the compiled program then comes from
JAX's disk cache as before. The results are those of the traced function.

A kept program is found by a key that holds everything its trace depends on, so that a stale
program is never used:

- a fingerprint of the code: every source file of hbgear, the versions of Python, jax, jaxlib,
  numpy and scipy (traces use ``scipy.fft``'s sizes), the JAX settings that change a trace, the
  backend;
- what the caller says the function closes over (`static_key`, e.g. the frozen
  ``HarmonicBalance`` settings) and its static arguments;
- the arguments' tree structure, with the class and static fields of every node, and each
  leaf's shape, dtype and weak type.

Arguments the fingerprint does not cover -- a node class defined outside hbgear (a user's system:
its source is not hashed), a static field or argument that is neither a plain value nor a frozen
dataclass of hbgear's made of such (described field by field), a leaf that is not an array or a
number -- are never kept: that call is the plain function's. So is every call
inside another function's trace, every call when no directory is enabled (the library's
default; the ``hbgear`` command enables one beside JAX's cache), and a call whose export fails or
whose kept file does not load (it is then exported again).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
import tempfile
from pathlib import Path

import numpy as np

from .typed_jit import node_types

__all__ = ["code_fingerprint", "disable", "enable", "persistent", "stats"]

#: Programs of one code fingerprint go to a folder named by its first characters.
FINGERPRINT_CHARS = 16
#: Folders of other fingerprints kept (the most recently used); older ones are removed.
KEEP_OTHER_VERSIONS = 3

_STATE = {"directory": None, "fingerprint": None, "pruned": False, "touched": False}
#: What this process did: programs exported and written, read back, and calls left to the plain function.
_STATS = {"exported": 0, "loaded": 0, "plain": 0}
_PLAIN_TYPES = (str, int, float, bool, complex, bytes, type(None))


def enable(directory: str | os.PathLike) -> Path:
    """Keep programs in `directory` (made with the first program kept; a directory that cannot
    be written only means that programs are not kept); **returns** it."""
    _STATE["directory"] = path = Path(directory)
    return path


def disable() -> None:
    _STATE["directory"] = None


def stats() -> dict:
    """This process's programs: ``directory`` (or ``None``: not kept), and the counts ``exported``
    (traced and written), ``loaded`` (read back) and ``plain`` (arguments not covered: traced)."""
    directory = _STATE["directory"]
    return {"directory": None if directory is None else str(directory), **_STATS}


def code_fingerprint(root: str | os.PathLike | None = None) -> str:
    """SHA-256 of every ``.py`` file under `root` (default: the hbgear package; path and content),
    the versions of Python, jax, jaxlib, numpy and scipy, the JAX settings a trace depends on and the
    default backend (computed once per process for the package)."""
    if root is None and _STATE["fingerprint"] is not None:
        return _STATE["fingerprint"]
    import jax
    import jaxlib
    import scipy

    digest = hashlib.sha256()
    base = Path(__file__).resolve().parents[1] if root is None else Path(root)
    for path in sorted(base.rglob("*.py")):
        digest.update(str(path.relative_to(base)).encode())
        digest.update(path.read_bytes())
    settings = [sys.version, jax.__version__, jaxlib.__version__, np.__version__, scipy.__version__,
                jax.default_backend()]
    for name in ("jax_enable_x64", "jax_default_matmul_precision", "jax_numpy_dtype_promotion",
                 "jax_numpy_rank_promotion", "jax_default_prng_impl", "jax_enable_checks"):
        settings.append(f"{name}={getattr(jax.config, name, None)!r}")
    digest.update(repr(settings).encode())
    if root is None:
        _STATE["fingerprint"] = digest.hexdigest()
    return digest.hexdigest()


class _NotCovered(Exception):
    """A value the key cannot describe completely."""


def _describe(value):
    """A complete, plain description of a static value for the key: plain values with their
    type; tuples and lists item by item; a frozen dataclass of hbgear's field by field (every
    field, whatever its ``repr``). **Raises** :class:`_NotCovered` for anything else."""
    import dataclasses

    if isinstance(value, _PLAIN_TYPES):
        return type(value).__name__, value
    if isinstance(value, (tuple, list)):
        return type(value).__name__, tuple(_describe(v) for v in value)
    kind = type(value)
    if dataclasses.is_dataclass(value) and not isinstance(value, type) and _own_class(kind) \
            and kind.__dataclass_params__.frozen:
        return (f"{kind.__module__}.{kind.__qualname__}",
                tuple((f.name, _describe(getattr(value, f.name))) for f in dataclasses.fields(value)))
    raise _NotCovered(kind)


def _own_class(cls) -> bool:
    module = getattr(cls, "__module__", "") or ""
    return module in ("builtins", "collections") or module == "hbgear" or module.startswith("hbgear.")


def _describe_structure(treedef) -> tuple:
    """Every node's class and static fields (:func:`_describe`), depth first. **Raises**
    :class:`_NotCovered` for a node class from outside hbgear or a static field it cannot describe."""
    out = []

    def walk(node):
        data = node.node_data()
        if data is not None:
            cls, aux = data
            if not _own_class(cls):
                raise _NotCovered(cls)
            out.append((f"{cls.__module__}.{cls.__qualname__}", _describe(aux)))
        for child in node.children():
            walk(child)

    walk(treedef)
    return tuple(out)


_DTYPES: dict = {}  # dtype -> its canonical dtype's string (x64 on or off)


def _canonical(dtype) -> str | None:
    """The canonical dtype's string, or ``None`` for a dtype JAX does not take."""
    try:
        return _DTYPES[dtype]
    except KeyError:
        import jax

        try:
            text = np.dtype(jax.dtypes.canonicalize_dtype(dtype)).str
        except (TypeError, ValueError):
            text = None
        _DTYPES[dtype] = text
        return text


def _aval(leaf):
    """``(shape, dtype, weak)`` of a leaf, or ``None`` for anything but an array or a number."""
    if isinstance(leaf, np.ndarray):
        aval = leaf.shape, _canonical(leaf.dtype), False
    elif type(leaf) in (bool, int, float, complex):
        aval = (), _canonical(np.dtype(type(leaf))), True
    elif isinstance(leaf, np.generic):
        aval = (), _canonical(leaf.dtype), False
    else:
        import jax

        if not isinstance(leaf, jax.Array):
            return None
        aval = tuple(leaf.shape), _canonical(leaf.dtype), bool(getattr(leaf, "weak_type", False))
    return None if aval[1] is None else aval


#: The programs loaded or exported in this process, by file name (one compiled call each).
_PROGRAMS: dict = {}


class _Program:
    """One exported program: ``program(leaves)`` is its output tree for the flat argument leaves."""

    def __init__(self, exported, out_tree):
        import jax

        # every argument placed on the default device by the call itself: the program is then
        # the same for numpy, uncommitted and committed arrays (a compiled program's outputs are
        # committed; without this the call is compiled again when an argument changes kind)
        self.call = jax.jit(exported.call, in_shardings=jax.sharding.SingleDeviceSharding(jax.devices()[0]))
        self.out_tree = out_tree
        self.state = "new"  # "new" (not run yet), "ran", or "broken" (its first run raised)

    def __call__(self, leaves):
        import jax

        return jax.tree_util.tree_unflatten(self.out_tree, self.call(*leaves))


def persistent(fun, name: str, static_key=(), *, static_argnums=()):
    """`fun` (called with pytrees of arrays and numbers, traceable by ``jax.jit``), its programs
    kept on disk (module docstring). `name` names the files; `static_key` (its ``repr``) must
    describe everything `fun` closes over that is not in this module's code fingerprint;
    `static_argnums`: positional arguments that are static (hashable hbgear settings such as a
    ``HarmonicBalance``, or plain values), in the key by their ``repr``. Called inside a trace
    (any leaf a tracer) it is the plain function.

    The returned function has ``for_arguments(*args, **kwargs)``: the function for a loop of
    calls whose arguments all have the structure, shapes and dtypes of these and the same static
    arguments (a shape mismatch raises: an exported program checks its arguments; the static
    arguments of the calls are not looked at), without the per-call lookup."""
    static = (static_argnums,) if isinstance(static_argnums, int) else tuple(static_argnums)
    programs: dict = {}  # (static values, tree structure, node classes, avals) -> _Program, or None

    def split(args):
        return tuple(args[i] for i in static), tuple(a for i, a in enumerate(args) if i not in static)

    def lookup(args, kwargs):
        """``(program or None, leaves of the dynamic arguments)``."""
        import jax

        static_values, dynamic = split(args)
        leaves, tree = jax.tree_util.tree_flatten((dynamic, kwargs))
        if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
            return None, leaves  # inside another function's trace: that program holds this one
        avals = tuple(_aval(leaf) for leaf in leaves)
        try:
            signature = (static_values, tree, node_types((dynamic, kwargs)), avals)  # classes: typed_jit
            return programs[signature], leaves
        except KeyError:
            pass
        except TypeError:  # an unhashable static value: never kept
            return None, leaves
        try:
            static_description = _describe(static_values)
        except _NotCovered:
            program = None
            _STATS["plain"] += 1
        else:
            program = _program(_with_static(fun, static, static_values), name, (static_key, static_description),
                               tree, avals, _STATE["directory"])
        programs[signature] = program
        return program, leaves

    def call(*args, **kwargs):
        if _STATE["directory"] is None:
            return fun(*args, **kwargs)
        program, leaves = lookup(args, kwargs)
        if program is None or program.state == "broken":
            return fun(*args, **kwargs)
        if program.state == "ran":
            return program(leaves)
        try:  # a program that cannot run here (it should not happen): the plain function from now on
            result = program(leaves)
        except Exception:  # noqa: BLE001
            program.state = "broken"
            _STATS["plain"] += 1
            return fun(*args, **kwargs)
        program.state = "ran"
        return result

    def for_arguments(*args, **kwargs):
        program = None if _STATE["directory"] is None else lookup(args, kwargs)[0]
        if program is None or program.state == "broken":  # the plain function, bound too if it can be (typed_for)
            return fun.typed_for(*args, **kwargs) if hasattr(fun, "typed_for") else fun
        import jax

        def bound(*args, **kwargs):
            return program(jax.tree_util.tree_leaves((split(args)[1], kwargs)))

        return bound

    call.for_arguments = for_arguments
    call.persisted = fun  # the function it keeps programs of
    if hasattr(fun, "_cache_size"):  # typed_jit's count of compiled programs (tests)
        call._cache_size = fun._cache_size
    return call


def _with_static(fun, static: tuple, static_values: tuple):
    """``fun`` of the dynamic arguments only (the static ones put back in their places)."""
    if not static:
        return fun

    def dynamic_only(*dynamic, **kwargs):
        given, rest = dict(zip(static, static_values)), iter(dynamic)
        args = [given[i] if i in given else next(rest) for i in range(len(static) + len(dynamic))]
        return fun(*args, **kwargs)

    return dynamic_only


def _program(fun, name, static_key, tree, avals, directory) -> _Program | None:
    """The kept program for arguments (``(dynamic args, kwargs)``) of structure `tree` and leaves
    of `avals`: loaded, or exported and written; ``None`` when they cannot be kept (module
    docstring) or exporting fails."""
    try:
        if any(a is None for a in avals):
            raise _NotCovered("leaf")
        structure = _describe_structure(tree)
    except _NotCovered:
        _STATS["plain"] += 1
        return None
    fingerprint = code_fingerprint()  # `structure` names every node's class (what typed_jit keys on)
    key = hashlib.sha256(repr((fingerprint, name, repr(static_key), str(tree), structure, avals)).encode())
    path = Path(directory) / fingerprint[:FINGERPRINT_CHARS] / f"{name}-{key.hexdigest()[:40]}.bin"
    if path in _PROGRAMS:
        return _PROGRAMS[path]
    _PROGRAMS[path] = program = _load_or_export(fun, path, tree, avals)
    return program


def _load_or_export(fun, path: Path, tree, avals) -> _Program | None:
    import jax

    if path.exists():
        try:
            serialized, out_tree = pickle.loads(path.read_bytes())
            program = _Program(jax.export.deserialize(serialized), out_tree)
            _STATS["loaded"] += 1
            _touch(path.parent)
            return program
        except Exception:  # noqa: BLE001 -- a damaged or foreign file: exported again below
            pass
    out = {}

    def flat(*flat_leaves):
        a, k = jax.tree_util.tree_unflatten(tree, flat_leaves)
        result, out["tree"] = jax.tree_util.tree_flatten(fun(*a, **k))
        return result

    specs = [jax.ShapeDtypeStruct(shape, np.dtype(dtype), weak_type=weak) for shape, dtype, weak in avals]
    try:
        exported = jax.export.export(jax.jit(flat))(*specs)
        serialized = exported.serialize()
        data = pickle.dumps((serialized, out["tree"]), protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # noqa: BLE001 -- not exportable (e.g. flatbuffers missing): the plain function
        _STATS["plain"] += 1
        return None
    _write_atomic(path, data)
    _prune(path.parent)
    _STATS["exported"] += 1
    return _Program(exported, out["tree"])


def _touch(folder: Path) -> None:
    """Mark a fingerprint's folder used (its time orders :func:`_prune`); once per process."""
    if not _STATE["touched"]:
        _STATE["touched"] = True
        try:
            os.utime(folder)
        except OSError:
            pass


def _prune(current: Path) -> None:
    """Remove the folders of other code fingerprints (other hbgear or jax versions, edited
    sources) but the :data:`KEEP_OTHER_VERSIONS` most recently used; once per process."""
    if _STATE["pruned"]:
        return
    _STATE["pruned"] = True
    import shutil

    try:
        others = [d for d in current.parent.iterdir() if d.is_dir() and d != current]
        others.sort(key=lambda d: d.stat().st_mtime, reverse=True)
    except OSError:
        return
    for old in others[KEEP_OTHER_VERSIONS:]:
        shutil.rmtree(old, ignore_errors=True)


def _write_atomic(path: Path, data: bytes) -> None:
    """Write `data` to `path` through a temporary file and a rename (a reader never sees half a
    file); an unwritable directory only means the program is not kept."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except OSError:
        try:
            os.unlink(tmp)
        except OSError:
            pass
