"""Numba's on-disk kernel cache, invalidated when any source of the package changes.

numba's ``cache=True`` keys a compiled kernel by the time stamp and size of the file that
defines it, not by the files of the functions it calls and inlines. After an update that
changes only a callee (``git pull`` into an editable install), a kernel in an unchanged file
would be loaded compiled against the old callee: measured, ``montecarlo/sample.py``'s cached
kernel called the coupling force with its old signature and gave non-finite states. So the
package stamps its ``__pycache__`` with a hash of all its sources and deletes the cached
kernels (``*.nbi``, ``*.nbc``) when the hash changes. Only caches in the source tree are
handled; a cache directory of the user's own choosing (``NUMBA_CACHE_DIR``) is not touched.
Importing this module (the package does, before its kernel modules) checks the package.

numba's cache is also not safe for processes that compile at the same time (a dask cluster's
workers, the test suite's processes): a save reads a function's index, takes the first free
data-file number and writes index and data unlocked, so two processes saving two variants of
one function (the path loop's step kinds share a name) can both take number 1, and the index
can end up naming the other variant's machine code, which every later process would load.
:func:`serialize_cache_saves` makes those saves one at a time with a lock on the cache folder.
"""

from __future__ import annotations

import functools
import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["source_stamp", "clear_stale_kernels", "serialize_cache_saves"]

#: File in the package's ``__pycache__`` holding the hash of the sources the cache was built from.
STAMP_NAME = "numba-sources.sha256"


def source_stamp(root: Path) -> str:
    """SHA-256 (hex) over the relative paths and contents of every ``.py`` file under ``root``."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def clear_stale_kernels(root: Path) -> bool:
    """Delete the cached kernels under ``root``'s ``__pycache__`` folders unless its stamp
    matches the sources (:func:`source_stamp`), then write the stamp.

    Returns whether the cache was cleared. A read-only install (no stamp can be written) is
    left as it is: nothing can have changed its sources either.
    """
    stamp = source_stamp(root)
    mark = root / "__pycache__" / STAMP_NAME
    try:
        if mark.read_text() == stamp:
            return False
    except OSError:
        pass
    try:
        for cached in (*root.rglob("__pycache__/*.nbi"), *root.rglob("__pycache__/*.nbc")):
            cached.unlink(missing_ok=True)
        mark.parent.mkdir(exist_ok=True)
        mark.write_text(stamp)
    except OSError:
        return False
    return True



def _one_writer_at_a_time(save: Callable[..., None]) -> Callable[..., None]:
    """``save`` (numba's ``IndexDataCacheFile.save``) under an exclusive ``flock`` on the cache
    folder, held from reading the index to writing the data. A load needs no lock: an index
    entry whose data file is not written yet is a miss, and numba compiles again."""
    import fcntl

    @functools.wraps(save)
    def locked(self: Any, key: object, data: object) -> None:
        folder = os.open(self._cache_path, os.O_RDONLY)
        try:
            fcntl.flock(folder, fcntl.LOCK_EX)
            save(self, key, data)
        finally:
            os.close(folder)  # closing the descriptor releases the lock

    locked.serialized = True  # type: ignore[attr-defined]
    return locked


def serialize_cache_saves() -> bool:
    """Make numba's on-disk cache saves one at a time across processes (module docstring).

    Applies once per process; returns whether the saves are serialized. Where the platform has
    no ``flock`` (Windows) or numba's cache class has another shape, numba is left as it is and
    False is returned: concurrent cold compiles there can still race.
    """
    try:
        import fcntl  # noqa: F401
        from numba.core.caching import IndexDataCacheFile
    except ImportError:
        return False
    save = getattr(IndexDataCacheFile, "save", None)
    if save is None or "_cache_path" not in IndexDataCacheFile.__init__.__code__.co_names:
        return False
    if not getattr(save, "serialized", False):
        IndexDataCacheFile.save = _one_writer_at_a_time(save)
    return True


clear_stale_kernels(Path(__file__).parent)
serialize_cache_saves()
