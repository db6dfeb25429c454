"""The numba cache of the package is dropped when any of its sources changes."""

from __future__ import annotations

from pathlib import Path

import montecarlo
from montecarlo._cache import STAMP_NAME, clear_stale_kernels, source_stamp


def _tree(root: Path) -> Path:
    (root / "sub" / "__pycache__").mkdir(parents=True)
    (root / "kernel.py").write_text("def f(): return g()\n")
    (root / "sub" / "callee.py").write_text("def g(): return 1\n")
    return root / "sub" / "__pycache__" / "callee.g-1.py311.nbi"


def test_cached_kernels_survive_unchanged_sources_and_go_when_a_callee_changes(tmp_path: Path) -> None:
    cached = _tree(tmp_path)
    assert clear_stale_kernels(tmp_path)  # no stamp yet: cleared, stamped
    assert (tmp_path / "__pycache__" / STAMP_NAME).read_text() == source_stamp(tmp_path)
    cached.write_bytes(b"kernel")
    assert not clear_stale_kernels(tmp_path) and cached.exists()
    (tmp_path / "sub" / "callee.py").write_text("def g(): return 2\n")  # only the callee changes
    assert clear_stale_kernels(tmp_path) and not cached.exists()
    assert not clear_stale_kernels(tmp_path)


def test_the_package_is_stamped_with_its_own_sources() -> None:
    root = Path(montecarlo.__file__).parent
    assert (root / "__pycache__" / STAMP_NAME).read_text() == source_stamp(root)


def test_a_cache_save_waits_for_another_process_lock(tmp_path: Path) -> None:
    """A save (numba's ``IndexDataCacheFile.save``, serialized on import) blocks while another
    descriptor holds the folder's lock, as a second process's save would, and completes after."""
    import fcntl
    import os
    import threading

    from numba.core.caching import IndexDataCacheFile

    from montecarlo._cache import serialize_cache_saves

    assert serialize_cache_saves()
    cache = IndexDataCacheFile(str(tmp_path), "kernel", source_stamp=("stamp", 1))
    other = os.open(tmp_path, os.O_RDONLY)
    fcntl.flock(other, fcntl.LOCK_EX)
    saver = threading.Thread(target=cache.save, args=(("sig",), b"machine code"))
    saver.start()
    saver.join(0.3)
    held = saver.is_alive() and not list(tmp_path.glob("*.nbi"))
    os.close(other)
    saver.join(10)
    assert held, "the save did not wait for the lock"
    assert not saver.is_alive() and cache.load(("sig",)) == b"machine code"
