"""Point cache of scene runs: one JSON line per finished point, in the output folder.

The file doubles as the run log: each point is appended (and flushed) the moment it is
done, so an interrupted sweep loses nothing and the next run resumes where it stopped.
Points are keyed by harvester + method + accuracy (+ solver settings other than the seed),
so any scene that writes to the same folder reuses them. Failed points are logged but never
served from the cache: they are tried again on the next run (a solver may have become
available meanwhile).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..model import Harvester
from ..result import QUANTITIES, Stats, Status

__all__ = ["PointCache", "point_key", "point_seed"]

CACHE_NAME = "points.jsonl"
#: Solver settings that do not change the result's meaning: not part of the cache key
#: (Monte Carlo results do not depend on the thread count, and only statistically on the replica
#: batch; the seed is derived from the point).
_NOT_IN_KEY = ("seed", "progress", "threads", "batch")


def _canonical(h: Harvester, method: str, rtol: float | None, options: Mapping[str, Any]) -> str:
    opts = {key: val for key, val in options.items() if key not in _NOT_IN_KEY}
    return json.dumps(
        {"h": h.to_dict(), "method": method, "rtol": rtol, "options": opts},
        sort_keys=True, default=str,
    )


def point_key(h: Harvester, method: str, rtol: float | None, options: Mapping[str, Any]) -> str:
    """Cache key: hash of harvester, method, accuracy and settings (except those in ``_NOT_IN_KEY``)."""
    return hashlib.sha256(_canonical(h, method, rtol, options).encode()).hexdigest()[:24]


def point_seed(scene_name: str, h: Harvester) -> int:
    """Deterministic 32-bit seed of a point of a scene (same scene + point: same seed)."""
    text = scene_name + "|" + json.dumps(h.to_dict(), sort_keys=True)
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "little")


def stats_from_dict(d: Mapping[str, Any]) -> Stats:
    """Inverse of :meth:`Stats.to_dict`."""
    kwargs: dict[str, Any] = {}
    for name in QUANTITIES:
        kwargs[name] = d.get(name)
        kwargs[name + "_err"] = d.get(name + "_err")
    return Stats(
        status=Status(d["status"]), message=d.get("message", ""), method=d.get("method", ""),
        growth_rate=d.get("growth_rate"), info=d.get("info") or {}, **kwargs,
    )


class PointCache:
    """Append-only JSON-lines store of finished points, loaded once on open.

    Parameters
    ----------
    folder : Path
        Output folder; the file is ``folder / "points.jsonl"``.

    Attributes
    ----------
    skipped_lines : int
        Lines that could not be read (e.g. the last line of a run killed mid-write).
    """

    def __init__(self, folder: Path) -> None:
        self.path = Path(folder) / CACHE_NAME
        self._stats: dict[str, Stats] = {}
        self.skipped_lines = 0
        if self.path.exists():
            for line in self.path.read_text(encoding="utf-8").splitlines():
                if not line.strip():
                    continue
                try:
                    rec = json.loads(line)
                    if "stats" in rec:
                        self._stats[rec["key"]] = stats_from_dict(rec["stats"])
                except (ValueError, KeyError, TypeError):
                    self.skipped_lines += 1

    def __len__(self) -> int:
        return len(self._stats)

    def get(self, key: str) -> Stats | None:
        """The cached result of ``key``, or ``None``."""
        return self._stats.get(key)

    def put(self, key: str, h: Harvester, stats: Stats, extra: Mapping[str, Any]) -> None:
        """Store and append a finished point (flushed at once)."""
        self._stats[key] = stats
        self._append({"key": key, "harvester": h.to_dict(), **extra, "stats": stats.to_dict()})

    def log_failure(self, key: str, h: Harvester, status: str, message: str,
                    extra: Mapping[str, Any]) -> None:
        """Append a failed point to the log (not served from the cache later)."""
        self._append({"key": key, "harvester": h.to_dict(), **extra,
                      "failure": {"status": status, "message": message}})

    def _append(self, record: Mapping[str, Any]) -> None:
        # One write per line, flushed, so a kill leaves at most one partial last line.
        with self.path.open("a", encoding="utf-8") as fh:
            fh.write(json.dumps(record, default=str) + "\n")
            fh.flush()
