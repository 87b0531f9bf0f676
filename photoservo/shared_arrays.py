"""uint8 arrays in a file mapping that two processes of a session share (the simulator's camera
pairs, the recorder process's frame slots): one process `create`s it, the other maps the same
path, and `unlink` removes the name once both have it mapped (the mapping lives on until both
close it, so a killed session leaves no file behind after that). Not the standard library's
multiprocessing.shared_memory.SharedMemory: on Python 3.11 its resource tracker registers the
segment in the attaching process too and unlinks it (with a warning) when either exits
(`track=False` arrives in 3.13); a named file that is unlinked once both have mapped it has
neither problem."""

from __future__ import annotations

import math
import mmap
import os
import tempfile

import numpy as np


class SharedArrays:
    """`arrays`: uint8 views of the given `shapes`, one after the other in the mapping of `path`."""

    def __init__(self, path: str, shapes: list[tuple[int, ...]]) -> None:
        self.path, self.shapes = path, [tuple(s) for s in shapes]
        n = [math.prod(s) for s in self.shapes]
        with open(path, "r+b") as f:
            self._map = mmap.mmap(f.fileno(), sum(n))
        offsets = np.cumsum([0, *n[:-1]])
        self.arrays = [np.ndarray(s, np.uint8, self._map, int(o)) for s, o in zip(self.shapes, offsets)]

    @staticmethod
    def make_file(shapes: list[tuple[int, ...]], prefix: str) -> str:
        """A new zero-filled file for arrays of `shapes` (in /dev/shm where there is one); its path."""
        folder = "/dev/shm" if os.path.isdir("/dev/shm") else None
        fd, path = tempfile.mkstemp(prefix=prefix, dir=folder)
        with os.fdopen(fd, "wb") as f:
            f.truncate(sum(math.prod(s) for s in shapes))
        return path

    def unlink(self) -> None:
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass

    def close(self) -> None:
        self.arrays = []
        self._map.close()
