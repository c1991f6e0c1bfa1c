"""The server's memory: uploaded images and recent reconstructions, bounded, least recently used out.

Nothing here touches the file system: an image lives only as the array it was decoded to, so no
path a client sends is ever opened.
"""

from __future__ import annotations

import secrets
import threading
from collections import OrderedDict
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["StoredImage", "LRU", "new_image_id"]


@dataclass(frozen=True, eq=False)
class StoredImage:
    """An image the client opened.

    Attributes
    ----------
    image_id : str
        The name the client uses for it (URL-safe).
    name : str
        Display name (the upload's file name without folders, or the example's name).
    pixels : (H, W, C) float32
        As :func:`shadeform.io.images.load_pixels` returns it (linear), ``C`` 1 (gray) or 3
        (colour).
    mask : (H, W) bool or None
        A known object mask (the synthetic examples have their true one); None: found
        automatically from the chosen channel.
    suggested : dict or None
        Suggested :class:`shadeform.app.schema.ReconstructParams` fields, or None.
    photo : dict or None
        How a photo file was read: bit depth, encoding (8-bit files are sRGB and were made
        linear), what decided it, clipped fractions (:attr:`shadeform.io.images.Photo.info`
        less the channel); None for an example made in memory.
    """

    image_id: str
    name: str
    pixels: np.ndarray
    mask: np.ndarray | None = None
    suggested: dict[str, Any] | None = None
    photo: dict[str, Any] | None = None

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays."""
        return self.pixels.nbytes + (0 if self.mask is None else self.mask.nbytes)


def new_image_id() -> str:
    """A fresh random id: 16 hex digits, safe in a URL path segment."""
    return secrets.token_hex(8)


class LRU:
    """A thread-safe mapping bounded by item count and total bytes; the least recently used go.

    Parameters
    ----------
    max_items : int
        Most entries kept (pinned ones included).
    max_bytes : int
        Most bytes kept, by the sizes given to :meth:`put`. An entry larger than this alone is
        still kept (alone): the one just added is never evicted, so a caller can always use it.
    """

    def __init__(self, *, max_items: int, max_bytes: int) -> None:
        self.max_items = int(max_items)
        self.max_bytes = int(max_bytes)
        self._items: OrderedDict[Hashable, tuple[Any, int, bool]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def get(self, key: Hashable) -> Any | None:
        """The value for ``key`` (now the most recently used), or None."""
        with self._lock:
            item = self._items.get(key)
            if item is None:
                return None
            self._items.move_to_end(key)
            return item[0]

    def put(self, key: Hashable, value: Any, nbytes: int, *, pinned: bool = False) -> None:
        """Store ``value`` under ``key``, then evict unpinned entries, oldest first, to fit."""
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= old[1]
            self._items[key] = (value, int(nbytes), pinned)
            self._bytes += int(nbytes)
            for victim in [k for k, (_, _, pin) in self._items.items() if not pin and k != key]:
                if len(self._items) <= self.max_items and self._bytes <= self.max_bytes:
                    break
                self._bytes -= self._items.pop(victim)[1]

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)

    @property
    def nbytes(self) -> int:
        """Total bytes held."""
        with self._lock:
            return self._bytes
