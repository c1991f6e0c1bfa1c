"""One binary min-heap for the marching solvers (compiled), keyed by ``(key, item)``.

Fast marching (:mod:`shadeform.solvers.eikonal`) and the oblique solver's cone marching
(:mod:`shadeform.solvers.oblique`) both pop pixels in order of a key. The heap lives in three
preallocated arrays: ``keys`` and ``items`` (its entries) and ``where`` (an item's position in it,
-1 when it is not queued), so an item is queued at most once and its key can be lowered in place.
Equal keys pop the smaller item first, so the order never depends on the order of insertion.
The operations that take arrays are inlined into their callers' loops (numba's
``inline="always"``): a call of a compiled function counts references to its array arguments,
which costs more than a heap step.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def _before(key_a, item_a, key_b, item_b) -> bool:
    if key_a != key_b:
        return key_a < key_b
    return item_a < item_b


@numba.njit(cache=True, inline="always")
def _place(keys, items, where, i, key, item):
    """Put ``(key, item)`` at position ``i`` and note where the item is: the one step of both sifts."""
    keys[i] = key
    items[i] = item
    where[item] = i


@numba.njit(cache=True, inline="always")
def heap_update(keys, items, where, size, key, item):
    """Queue ``item`` with ``key``, or lower its key if it is queued with a larger one.

    Returns the new size. An item already queued with a key at or below ``key`` stays as it is.
    """
    i = where[item]
    if i < 0:
        i = size
        size += 1
    elif not _before(key, item, keys[i], item):
        return size
    while i > 0:
        parent = (i - 1) // 2
        if not _before(key, item, keys[parent], items[parent]):
            break
        _place(keys, items, where, i, keys[parent], items[parent])
        i = parent
    _place(keys, items, where, i, key, item)
    return size


@numba.njit(cache=True, inline="always")
def heap_pop(keys, items, where, size):
    """Remove the smallest ``(key, item)``; return ``(key, item, new size)``."""
    key = keys[0]
    item = items[0]
    where[item] = -1
    size -= 1
    if size == 0:
        return key, item, size
    last_key = keys[size]
    last_item = items[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and _before(keys[child + 1], items[child + 1], keys[child], items[child]):
            child += 1
        if not _before(keys[child], items[child], last_key, last_item):
            break
        _place(keys, items, where, i, keys[child], items[child])
        i = child
    _place(keys, items, where, i, last_key, last_item)
    return key, item, size


@numba.njit(cache=True, inline="always")
def heap_reserve(keys, items, size):
    """``keys`` and ``items`` with room for one more entry: the same arrays, or copies twice as
    long when ``size`` fills them (a heap started small grows with its front, not the image)."""
    if size < keys.size:
        return keys, items
    grown_keys = np.empty(2 * keys.size, keys.dtype)
    grown_items = np.empty(2 * items.size, items.dtype)
    grown_keys[:size] = keys[:size]
    grown_items[:size] = items[:size]
    return grown_keys, grown_items


def index_dtype(n_items: int) -> type:
    """The integer type of item numbers ``0..n_items-1`` and heap positions: int32 while they
    fit (half the memory of a pixel-sized array), int64 beyond."""
    return np.int32 if n_items < 2**31 else np.int64


def new_heap(n_items: int, capacity: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Empty ``keys``, ``items`` and ``where`` arrays for items ``0..n_items-1``.

    ``keys`` and ``items`` hold ``capacity`` entries (default ``n_items``, never full); a caller
    that starts smaller calls :func:`heap_reserve` before each :func:`heap_update`. ``where``
    always has one entry per item.
    """
    capacity = n_items if capacity is None else max(int(capacity), 1)
    dtype = index_dtype(n_items)
    return np.empty(capacity), np.empty(capacity, dtype), np.full(n_items, -1, dtype)
