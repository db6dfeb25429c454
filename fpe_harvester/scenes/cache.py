"""Files of a scene run: the point cache (one JSON line per finished point) and atomic outputs.

The cache file ``points.jsonl`` doubles as the run log: each point is appended the moment
it is done, so an interrupted sweep loses nothing and the next run resumes where it stopped.
Points are keyed by harvester + method + accuracy (+ solver settings other than the seed),
so any scene that writes to the same folder reuses them. Failed points are logged but never
served from the cache: they are tried again on the next run (a solver may have become
available meanwhile).

Faults the format survives
--------------------------
* **A run killed at any moment** (SIGKILL, power cut): each line is written by a single
  ``os.write`` of the whole line on an ``O_APPEND`` descriptor, so a kill leaves at most one
  partial last line. That line is skipped when read, and the next append first ends it with
  a newline, so it never glues onto a good record.
* **Garbled lines** (a truncated line, a flipped byte, inserted junk, a NaN): every line
  starts with a checksum, ``{"sum":"<16 hex digits>",`` and then the record's fields: the
  first 64 bits of the SHA-256 of the record's own JSON text (the rest of the line with its
  ``{``), so any changed byte is caught without re-serializing. A record must also pass
  validation (key, status, finite numbers). A line that fails is skipped and counted
  (:attr:`PointCache.skipped_lines`, with reasons in :attr:`PointCache.problems`); its point
  is computed again. Lines without a checksum, written by earlier versions, are accepted when
  they pass validation and hold no unknown fields.
* **Two runs writing one folder at once**: appends take an exclusive advisory lock
  (``fcntl.flock`` on the cache file; POSIX only, elsewhere the single ``O_APPEND`` write is
  the only guard) and reading takes a shared one, so lines never interleave. Each run reads
  the cache once, when it starts, and computes what it did not find there: both runs may
  compute and append the same point. Duplicates of a key are harmless: the last valid line
  wins (seeded solvers give identical lines). Each run writes its outputs (CSV, JSON, table,
  figures) through a temporary file renamed into place (:func:`atomic_path`), so a reader
  sees either a complete old or a complete new file, each with every point of the scene once.

Lines are not ``fsync``-ed: a kill loses nothing the kernel has, and what a power cut loses
is at worst a garbled tail that the checksum catches.
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..model import Harvester
from ..result import QUANTITIES, Stats, Status, harvester_from_dict

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX
    fcntl = None  # type: ignore[assignment]

__all__ = ["PointCache", "atomic_path", "point_key", "point_seed"]

CACHE_NAME = "points.jsonl"
#: Solver settings that do not change the result's meaning: not part of the cache key
#: (Monte Carlo results do not depend on the thread count, and only statistically on the replica
#: batch; the seed is derived from the point).
_NOT_IN_KEY = ("seed", "progress", "threads", "batch")
#: Fields a record may hold (besides the checksum ``"sum"``).
_FIELDS = frozenset({"key", "harvester", "scene", "seed", "method", "stats", "failure"})
#: Problems kept verbatim (the count covers all).
_MAX_PROBLEMS = 20


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
    """Inverse of :meth:`Stats.to_dict`.

    Raises
    ------
    ValueError, TypeError, KeyError
        ``d`` is not what :meth:`Stats.to_dict` writes (a missing status, an unknown status,
        a number that is not a finite float, a harvester that is not one).
    """
    kwargs: dict[str, Any] = {}
    for name in QUANTITIES:
        for key in (name, name + "_err"):
            value = d.get(key)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
                raise TypeError(f"{key} must be a number or null, got {value!r}")
            kwargs[key] = value
    message, method, info = d.get("message", ""), d.get("method", ""), d.get("info") or {}
    if not isinstance(message, str) or not isinstance(method, str) or not isinstance(info, Mapping):
        raise TypeError("message and method must be strings and info an object")
    system = d.get("harvester")
    if system is not None and not isinstance(system, Mapping):
        raise TypeError("harvester must be an object")
    return Stats(status=Status(d["status"]), message=message, method=method,
                 growth_rate=d.get("growth_rate"), info=info,
                 harvester=None if system is None else harvester_from_dict(system), **kwargs)


#: Every line this version writes starts with its checksum: ``{"sum":"<16 hex>",`` + record.
_SUM_OPEN, _SUM_LEN = b'{"sum":"', 16


def _digest(body: bytes) -> bytes:
    return hashlib.sha256(body).hexdigest()[:_SUM_LEN].encode()


def _encode(record: Mapping[str, Any]) -> bytes:
    """One cache line: the checksum of the record's JSON text, then the record, then a newline."""
    body = json.dumps(record, default=str, separators=(",", ":")).encode()
    return _SUM_OPEN + _digest(body) + b'",' + body[1:] + b"\n"  # records are never empty


def _decode(raw: bytes) -> dict[str, Any]:
    """The record of one cache line, checked.

    Raises
    ------
    ValueError
        The line is not UTF-8 JSON, its checksum does not match, or the record is not valid
        (the message says which).
    TypeError
        The line is JSON but not an object.
    """
    head = len(_SUM_OPEN) + _SUM_LEN
    checked = raw.startswith(_SUM_OPEN)
    if checked:
        body = b"{" + raw[head + 2:]
        if raw[head:head + 2] != b'",' or _digest(body) != raw[len(_SUM_OPEN):head]:
            raise ValueError("checksum mismatch")
        raw = body
    try:
        rec = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"not a JSON line ({type(exc).__name__})") from None
    if not isinstance(rec, dict):
        raise TypeError("not a JSON object")
    if not checked and not rec.keys() <= _FIELDS:
        raise ValueError(f"no checksum and unknown fields {sorted(rec.keys() - _FIELDS)}")
    if not isinstance(rec.get("key"), str) or not rec["key"]:
        raise ValueError("no key")
    if ("stats" in rec) == ("failure" in rec):
        raise ValueError("neither stats nor failure (or both)")
    if "stats" in rec:
        if not isinstance(rec["stats"], Mapping):
            raise ValueError("stats is not an object")
        try:
            rec["stats"] = stats_from_dict(rec["stats"])
        except (ValueError, TypeError, KeyError) as exc:
            raise ValueError(f"invalid stats ({type(exc).__name__}: {exc})") from None
    return rec


def _lock(fd: int, exclusive: bool) -> None:
    if fcntl is not None:
        fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)


class PointCache:
    """Append-only JSON-lines store of finished points, read once on open.

    Parameters
    ----------
    folder : Path
        Output folder; the file is ``folder / "points.jsonl"``.

    Attributes
    ----------
    skipped_lines : int
        Lines that were read but not used: partial (a run killed mid-write), garbled (checksum
        mismatch, not JSON) or invalid (missing key, unknown status, non-finite number).
        Their points are computed again.
    problems : list of str
        ``"line <number>: <reason>"`` for the first skipped lines.
    """

    def __init__(self, folder: Path) -> None:
        self.path = Path(folder) / CACHE_NAME
        self._stats: dict[str, Stats] = {}
        self.skipped_lines = 0
        self.problems: list[str] = []
        if self.path.exists():
            self._read()

    def _read(self) -> None:
        with self.path.open("rb") as fh:
            _lock(fh.fileno(), exclusive=False)
            data = fh.read()
        for number, raw in enumerate(data.split(b"\n"), start=1):
            if not raw.strip():
                continue
            try:
                rec = _decode(raw)
            except (ValueError, TypeError) as exc:
                self.skipped_lines += 1
                if len(self.problems) < _MAX_PROBLEMS:
                    self.problems.append(f"line {number}: {exc}")
                continue
            if "stats" in rec:
                self._stats[rec["key"]] = rec["stats"]

    def __len__(self) -> int:
        return len(self._stats)

    def get(self, key: str) -> Stats | None:
        """The cached result of ``key``, or ``None``."""
        return self._stats.get(key)

    def put(self, key: str, h: Harvester, stats: Stats, extra: Mapping[str, Any]) -> None:
        """Store and append a finished point (written at once)."""
        self._stats[key] = stats
        self._append({"key": key, "harvester": h.to_dict(), **extra, "stats": stats.to_dict()})

    def log_failure(self, key: str, h: Harvester, status: str, message: str,
                    extra: Mapping[str, Any]) -> None:
        """Append a failed point to the log (not served from the cache later)."""
        self._append({"key": key, "harvester": h.to_dict(), **extra,
                      "failure": {"status": status, "message": message}})

    def _append(self, record: Mapping[str, Any]) -> None:
        data = _encode(record)
        fd = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT, 0o666)
        try:
            _lock(fd, exclusive=True)  # released by close
            size = os.fstat(fd).st_size
            if size and _byte_at(fd, size - 1) != b"\n":
                data = b"\n" + data  # end the partial line a killed run left
            written = os.write(fd, data)
            while written < len(data):  # a short write (disk full, signal): finish the line
                written += os.write(fd, data[written:])
        finally:
            os.close(fd)


def _byte_at(fd: int, offset: int) -> bytes:
    if hasattr(os, "pread"):
        return os.pread(fd, 1, offset)
    os.lseek(fd, offset, os.SEEK_SET)  # pragma: no cover - not POSIX
    return os.read(fd, 1)  # pragma: no cover


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path next to ``path`` that replaces ``path`` when the block succeeds.

    A reader of ``path`` sees the complete old file or the complete new one, never a partial
    write; a failed or killed writer leaves ``path`` as it was. The temporary name keeps the
    suffix (plotting infers the format from it).

    >>> import tempfile
    >>> target = Path(tempfile.mkdtemp()) / "rows.csv"
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("a,b\\n")
    >>> target.read_text()
    'a,b\\n'
    """
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text_atomic(path: Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` through :func:`atomic_path`; return ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)
