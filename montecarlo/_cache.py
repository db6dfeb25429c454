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
"""

from __future__ import annotations

import hashlib
from pathlib import Path

__all__ = ["source_stamp", "clear_stale_kernels"]

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


clear_stale_kernels(Path(__file__).parent)
