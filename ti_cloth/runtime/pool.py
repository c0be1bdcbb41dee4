"""Kernel arguments reused across simulations, so a process that builds many stays flat in memory.

Taichi compiles a kernel once per set of template arguments, keyed by the argument objects, and
never frees what it compiled (the C++ program keeps every kernel). A simulation built, stepped
and dropped would leave its kernels behind (megabytes each: docs/performance.md), so a study
or an advisor building hundreds of simulations would grow without bound. So the objects a
Simulation passes to kernels come from here:

- objects holding fields (Model, State, the stages' fields) are *lent*: one simulation uses
  each at a time; when it is collected they go back to a free list under their structure key
  (everything their kernels read at compile time), and the next simulation of that structure
  gets them back, with the kernels already compiled for them. Its data is uploaded anew.
- settings (ForceSettings, integrators) are *kept* alive: Taichi keys a template argument by a
  weak reference, and weak references to live objects compare like the objects themselves, so
  a new simulation's equal settings find the kernels compiled for the kept copy (the pool's
  own copy: a user's integrator is never shared between simulations).

At most FREE_LIMIT objects of FREE_BYTES in all wait in free lists (the longest-unused go
first; one bigger than FREE_BYTES is never kept, so a big simulation's memory goes back when it
is dropped) and KEPT_LIMIT settings are kept: a sweep over ever new structures stays bounded in
fields and in Taichi's field trees (its kernels are new ones: that is Taichi's and cannot be
helped). Free objects never cost a live simulation its field trees: when Taichi's run short
(backend.on_tree_shortage) the free lists are emptied. `ti_cloth.init` starts a new runtime:
what was pooled before belongs to the old one and is dropped.
"""

from __future__ import annotations

import copy
import weakref
from collections import OrderedDict
from collections.abc import Callable, Hashable

from . import backend

FREE_LIMIT = 64          # objects waiting to be lent again, over every structure
FREE_BYTES = 256 << 20   # their memory, estimated by the borrower
KEPT_LIMIT = 64          # immutable settings kept alive for their kernels


class Pool:
    """Free lists of lent objects by structure key, and kept settings, of one Taichi runtime."""

    def __init__(self):
        self._generation = backend.generation()
        self._free: OrderedDict[tuple, object] = OrderedDict()   # (key, serial, bytes) -> object
        self._kept: OrderedDict[object, object] = OrderedDict()
        self._serial = 0
        backend.on_tree_shortage(self.release)

    def lend(self, key: Hashable, make: Callable[[], object], borrower,
             size: int) -> tuple[object, bool]:
        """(an object of structure `key` and about `size` bytes, whether it was lent before):
        a free one, the most recently given back first, else make(). It goes back when
        `borrower` is collected."""
        self._check_runtime()
        found = next((k for k in reversed(self._free) if k[0] == key), None)
        obj = self._free.pop(found) if found is not None else make()
        finalizer = weakref.finalize(borrower, self._give_back, key, obj, size, self._generation)
        finalizer.atexit = False
        return obj, found is not None

    def keep(self, value):
        """The kept setting equal to `value`, else a copy of `value`, kept from now on. Pass
        the kept one to kernels (Taichi's keys hold weak references to what was passed, so
        the kernels compiled for it serve every equal setting while it lives); it is the
        pool's own copy, never a user's object, so simulations sharing it share nothing a
        user reads."""
        self._check_runtime()
        kept = self._kept.pop(value, None)
        if kept is None:
            kept = copy.copy(value)
        self._kept[kept] = kept
        while len(self._kept) > KEPT_LIMIT:
            self._kept.popitem(last=False)
        return kept

    def free_count(self) -> int:
        """How many objects wait to be lent."""
        return len(self._free)

    def free_bytes(self) -> int:
        """Their memory [bytes], as estimated when they were lent."""
        return sum(k[2] for k in self._free)

    def release(self) -> None:
        """Empty the free lists: their fields go back as their objects are collected."""
        self._free.clear()

    def _give_back(self, key, obj, size: int, generation: int) -> None:
        if generation != self._generation or size > FREE_BYTES:
            return
        self._serial += 1
        self._free[(key, self._serial, size)] = obj
        while len(self._free) > FREE_LIMIT or self.free_bytes() > FREE_BYTES:
            self._free.popitem(last=False)

    def _check_runtime(self) -> None:
        if self._generation != backend.generation():
            self._generation = backend.generation()
            self._free.clear()
            self._kept.clear()


POOL = Pool()
