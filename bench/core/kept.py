"""What a process keeps of work it would otherwise repeat: the last few results, by a digest of their inputs."""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Callable, Hashable, TypeVar

import numpy as np

V = TypeVar("V")


def read_only(array: np.ndarray) -> np.ndarray:
    """``array``, no longer writable: a kept value is handed to every caller that asks for it again."""
    array.setflags(write=False)
    return array


def digest(*arrays: np.ndarray | None) -> tuple:
    """What identifies ``arrays`` (``None`` among them too): each one's shape and a hash of all their bytes."""
    h = hashlib.blake2b(digest_size=16)
    shapes = []
    for array in arrays:
        if array is None:
            shapes.append(None)
            continue
        array = np.ascontiguousarray(array)
        shapes.append((array.dtype.str, array.shape))
        h.update(memoryview(array).cast("B"))
    return tuple(shapes), h.digest()


class Kept:
    """The last ``size`` values made, by key: one asked for again is given, not made again."""

    def __init__(self, size: int):
        self.size = size
        self._values: OrderedDict = OrderedDict()

    def get(self, key: Hashable, make: Callable[[], V]) -> V:
        if key not in self._values:
            self._values[key] = make()
            while len(self._values) > self.size:
                self._values.popitem(last=False)
        self._values.move_to_end(key)
        return self._values[key]

    def __len__(self) -> int:
        return len(self._values)

    def clear(self) -> None:
        self._values.clear()
