"""Parallel work: how many worker threads or processes this process may use."""

from __future__ import annotations

import os

__all__ = ["default_threads"]


def default_threads() -> int:
    """Number of worker threads: the CPUs this process may use (its affinity mask on Linux).

    Examples
    --------
    >>> default_threads() >= 1
    True
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - non-Linux
        return max(1, os.cpu_count() or 1)
