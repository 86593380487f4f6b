"""The twin's disk cache of response tables: its files, their atomic writes and pruning.

:class:`sim.truth.TruthOptics` keeps the Kirchhoff response tables of a truth in one
``.npz`` file per (truth content, settings, table code) under the user cache directory
(:func:`sim.assembly.twin_cache_dir`; ``[sim.twin] cache = false`` turns it off). The
file's name carries the code key (:func:`sim.truth.table_code_key`), so files written by
another version of the twin (another branch, an older checkout: the directory is per user,
not per checkout) can be told apart and dropped:

* **atomic writes** (:func:`write_atomic`): a temporary file beside the target, flushed,
  then ``os.replace``: a reader never sees half a file, and two writers of the same
  tables leave one whole file;
* **pruning after every write** (:func:`prune`): temporary files a crashed writer left
  (older than :data:`TMP_MAX_AGE_S`), files of another code version not used for
  :data:`FOREIGN_MAX_AGE_S` (a file read is marked used: its mtime is the last use), then
  the least recently used files until the directory holds at most :data:`MAX_CACHE_BYTES`
  (never the file just written);
* ``goniolab sim cache`` shows the location and size and ``--clear`` empties it.

Only files named by this module are ever counted or removed: the directory may hold
anything else.
"""

from __future__ import annotations

import contextlib
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "FOREIGN_MAX_AGE_S",
    "MAX_CACHE_BYTES",
    "TMP_MAX_AGE_S",
    "CacheEntry",
    "CacheInfo",
    "cache_file",
    "clear",
    "mark_used",
    "prune",
    "scan",
    "write_atomic",
]

#: The most the cache directory may hold after a write, bytes (least recently used go
#: first). A table file is 30-60 MB per sample at the shipped settings and reaches ~1 GB
#: for a large truth: 4 GB keeps a session's samples without rebuilding them in turn.
MAX_CACHE_BYTES = 4_000_000_000
#: A file written by another version of the table code is dropped once unused this long, s
#: (a day: another checkout in use on the machine keeps its files meanwhile).
FOREIGN_MAX_AGE_S = 24 * 3600.0
#: A temporary file this old was left by a writer that died, s.
TMP_MAX_AGE_S = 3600.0
#: Length of the code key in a file name (hex digits).
CODE_CHARS = 12

_NAME = re.compile(r"^twin-(?:(?P<code>.+)-)?(?P<key>[0-9a-f]{20})\.npz$")
#: temporary files: goniolab._atomic's ``.<name>.<random>.tmp`` and the ``<stem>.<pid>.tmp.npz``
#: of the writes before this module
_TMP = re.compile(r"^(\.twin-.*\.tmp|twin-.+\.\d+\.tmp\.npz)$")


def cache_file(cache_dir: str | Path, code_key: str, content_key: str) -> Path:
    """The file of the tables of ``content_key`` (20 hex digits) written by the table code
    ``code_key`` (:func:`sim.truth.table_code_key`)."""
    return Path(cache_dir) / f"twin-{code_key[:CODE_CHARS]}-{content_key}.npz"


@dataclass(frozen=True, slots=True)
class CacheEntry:
    """One file of the cache: ``code`` is the table code it was written by (``None``: a
    file named before the code key was in the name, i.e. an older version's)."""

    path: Path
    size_bytes: int
    mtime: float
    code: str | None
    temporary: bool = False


@dataclass(frozen=True, slots=True)
class CacheInfo:
    """The cache directory's table files and temporary files."""

    directory: Path
    entries: tuple[CacheEntry, ...]

    @property
    def total_bytes(self) -> int:
        """Bytes of every table and temporary file."""
        return sum(e.size_bytes for e in self.entries)

    def of_code(self, code_key: str) -> tuple[CacheEntry, ...]:
        """The table files written by ``code_key``."""
        code = code_key[:CODE_CHARS]
        return tuple(e for e in self.entries if not e.temporary and e.code == code)

    def others(self, code_key: str) -> tuple[CacheEntry, ...]:
        """Every other file (other or older code versions, temporary files)."""
        mine = set(self.of_code(code_key))
        return tuple(e for e in self.entries if e not in mine)


def scan(cache_dir: str | Path) -> CacheInfo:
    """The cache's files (an absent directory holds none)."""
    d = Path(cache_dir)
    entries: list[CacheEntry] = []
    try:
        names = sorted(os.listdir(d))
    except (FileNotFoundError, NotADirectoryError):
        names = []
    for name in names:
        m = _NAME.match(name)
        tmp = _TMP.match(name) is not None
        if m is None and not tmp:
            continue
        try:
            st = (d / name).stat()
        except OSError:
            continue  # removed meanwhile
        code = m.group("code") if m is not None else None
        entries.append(CacheEntry(d / name, st.st_size, st.st_mtime, code, temporary=tmp))
    return CacheInfo(d, tuple(entries))


def _remove(entry: CacheEntry) -> bool:
    try:
        entry.path.unlink()
    except FileNotFoundError:
        return False  # another process pruned it
    except OSError:
        return False  # not ours to remove (permissions): left, counted next time
    return True


def prune(
    cache_dir: str | Path,
    *,
    code_key: str,
    keep: Path | None = None,
    max_bytes: int = MAX_CACHE_BYTES,
    foreign_max_age_s: float = FOREIGN_MAX_AGE_S,
    tmp_max_age_s: float = TMP_MAX_AGE_S,
    now: float | None = None,
) -> list[CacheEntry]:
    """Remove what the cache need not keep (module docstring) and return it.

    Parameters
    ----------
    code_key
        The running table code's key: files of any other are "foreign".
    keep
        A file never removed (the one just written).
    max_bytes
        Least recently used files go until the table files total at most this.
    foreign_max_age_s, tmp_max_age_s
        Foreign files and temporary files unused for longer are removed.
    now
        The present (``time.time()``), for tests.
    """
    t = time.time() if now is None else now
    code = code_key[:CODE_CHARS]
    kept_path = None if keep is None else Path(keep)
    removed: list[CacheEntry] = []
    live: list[CacheEntry] = []
    for e in scan(cache_dir).entries:
        if e.path == kept_path:
            live.append(e)
        elif e.temporary:
            if t - e.mtime > tmp_max_age_s and _remove(e):
                removed.append(e)
        elif e.code != code and t - e.mtime > foreign_max_age_s:
            if _remove(e):
                removed.append(e)
        else:
            live.append(e)
    total = sum(e.size_bytes for e in live if not e.temporary)
    for e in sorted((e for e in live if not e.temporary), key=lambda e: e.mtime):
        if total <= max_bytes:
            break
        if e.path == kept_path:
            continue
        if _remove(e):
            removed.append(e)
        total -= e.size_bytes
    return removed


def clear(cache_dir: str | Path) -> list[CacheEntry]:
    """Remove every table file and temporary file of the cache; return them."""
    return [e for e in scan(cache_dir).entries if _remove(e)]


def mark_used(path: Path) -> None:
    """Mark a cache file as just used (its mtime: the least recently used go first)."""
    with contextlib.suppress(OSError):
        os.utime(path)


def write_atomic(path: Path, write: Callable[[Path], object]) -> None:
    """Create the directory, then write ``path`` whole or not at all: ``write(tmp)`` fills
    a temporary file beside it (``.<name>.<random>.tmp``), which is flushed to disk and
    moved over ``path`` (``os.replace``, atomic within a directory on POSIX and Windows);
    on any failure the temporary file is removed and ``path`` is as it was.

    Raises
    ------
    OSError
        Nothing was written.
    """
    import tempfile

    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        write(tmp)
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; the cache is the user's, readable
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
