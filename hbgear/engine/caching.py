"""A small bounded cache for values the engine builds once per content key (rules, frozen
operators, jump layouts, the zeros of a factorisation's shape)."""

from __future__ import annotations

from collections import OrderedDict

__all__ = ["BoundedCache"]


class BoundedCache:
    """At most `size` entries keyed on content (hashable keys built from values, never ``id()``);
    the least recently used entry leaves first."""

    def __init__(self, size: int):
        self.size = size
        self._data: OrderedDict = OrderedDict()

    def get_or_make(self, key, make):
        """The value of `key`, made by ``make()`` (and kept) when it is not here."""
        if key in self._data:
            self._data.move_to_end(key)
            return self._data[key]
        value = self._data[key] = make()
        if len(self._data) > self.size:
            self._data.popitem(last=False)
        return value

    def clear(self) -> None:
        self._data.clear()

    def __len__(self) -> int:
        return len(self._data)
