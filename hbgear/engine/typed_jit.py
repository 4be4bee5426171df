r"""``jax.jit`` whose compiled programs are told apart by the classes in their pytree arguments.

In jax 0.10 (0.10.0 to 0.10.2; 0.6.2, 0.7.0, 0.8.0, 0.9.0 and 0.9.2 are sound), two tree
structures built by ``jax.tree_util.register_dataclass`` compare *equal* whenever they have the same
shape of nodes and leaves, whatever their classes (and field names); their hashes differ, and
``jax.jit``'s cache of compiled programs then sometimes hands a call of one class the program
traced for the other. Two systems of different classes with the same leaves (a gated oscillator
with and without declared event functions; two friction laws with one coefficient each) can run
each other's equations: a silent wrong answer. Measured with 100 one-field classes through one
jitted function, each class's call in turn: 7 to 13 of them got another class's program (five
processes; which ones changes from process to process, as class hashes follow memory addresses).

:func:`typed_jit` adds the classes of every node of its dynamic arguments
(:func:`node_types`: a few microseconds a call, its walk memoised per structure) as one more static argument, so the
compiled program is chosen by class identity too. Use it for every compiled function that takes
a system (or anything holding user classes) as a traced argument.
"""

from __future__ import annotations

import functools

import jax

from .caching import BoundedCache

__all__ = ["node_types", "typed_jit"]


def _types_of(treedef) -> tuple:
    data = treedef.node_data()
    own = () if data is None else (data[0],)
    for child in treedef.children():
        own += _types_of(child)
    return own


#: node_types per tree structure: a dict compares the full hashes first (they differ between
#: classes) and only then the broken equality, so a structure finds its own entry.
_TYPES = BoundedCache(256)


def node_types(tree) -> tuple:
    """The class of every node of `tree`'s structure, depth first (leaves left out)."""
    structure = jax.tree_util.tree_structure(tree)
    return _TYPES.get_or_make(structure, lambda: _types_of(structure))


def typed_jit(fun=None, *, static_argnums=()):
    """``jax.jit(fun, static_argnums=...)`` keyed also on :func:`node_types` of the other
    positional and all keyword arguments. Usable as ``@typed_jit`` or
    ``@partial(typed_jit, static_argnums=0)``, on functions and methods."""
    if fun is None:
        return functools.partial(typed_jit, static_argnums=static_argnums)
    static = (static_argnums,) if isinstance(static_argnums, int) else tuple(static_argnums)

    def with_types(types, static_values, dynamic, kwargs):
        given, rest = dict(zip(static, static_values)), iter(dynamic)
        args = [given[i] if i in given else next(rest) for i in range(len(static_values) + len(dynamic))]
        return fun(*args, **kwargs)

    with_types.__name__ = getattr(fun, "__name__", "typed")  # the program's name in profiles and the disk cache
    with_types.__qualname__ = getattr(fun, "__qualname__", with_types.__name__)
    compiled = jax.jit(with_types, static_argnums=(0, 1))

    def split(args):
        return tuple(args[i] for i in static), tuple(a for i, a in enumerate(args) if i not in static)

    @functools.wraps(fun)
    def call(*args, **kwargs):
        static_values, dynamic = split(args)
        return compiled(node_types((dynamic, kwargs)), static_values, dynamic, kwargs)

    def typed_for(*args, **kwargs):
        """The compiled function with the node types of these arguments fixed (those that hold
        classes, given as the calls will give them), for a loop that calls it many times with
        arguments of the same classes: the walk is done once, not per call."""
        types = node_types((split(args)[1], kwargs))

        def bound(*args, **kwargs):
            static_values, dynamic = split(args)
            return compiled(types, static_values, dynamic, kwargs)

        return bound

    call.typed_for = typed_for
    call._cache_size = compiled._cache_size  # the programs compiled so far (tests)
    return call
