"""Guard of numba's on-disk cache against stale callees.

numba's ``cache=True`` keys a compiled function on its own source file's time stamp only: when a function
it calls (in another module) changes, the caller's cached machine code still holds the old callee.
:func:`guard` stamps the cache with a hash of every source file of the package and, when the hash
changed since the cache was written, deletes the package's cached index/data files before anything is
compiled or loaded, so every function recompiles against the current callees. The only file I/O of
``sim_core``; it runs once, from ``sim_core/__init__.py``.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

__all__ = ["cache_dirs", "guard", "source_hash", "stamp_path"]

STAMP_NAME = "numba-source.sha256"
CACHE_SUFFIXES = (".nbi", ".nbc")


def source_hash(package_dir: Path) -> str:
    """SHA-256 over the names and contents of the package's ``*.py`` files (sorted)."""
    digest = hashlib.sha256()
    for path in sorted(package_dir.rglob("*.py")):
        digest.update(path.relative_to(package_dir).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def cache_dirs(package_dir: Path) -> list[Path]:
    """Where numba caches the package's functions: the ``__pycache__`` folders beside the sources, or, when
    ``NUMBA_CACHE_DIR`` is set, the folders named like the package under it (numba mirrors the source path)."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    if user:
        return sorted(p for p in Path(user).rglob(package_dir.name) if p.is_dir())
    return sorted(p for p in package_dir.rglob("__pycache__") if p.is_dir())


def stamp_path(package_dir: Path) -> Path:
    """File holding the source hash the cache was written for."""
    user = os.environ.get("NUMBA_CACHE_DIR")
    root = Path(user) if user else package_dir / "__pycache__"
    return root / f"{package_dir.name}-{STAMP_NAME}"


def guard(package_dir: Path) -> bool:
    """Delete the package's numba cache files if its sources changed since they were written; True if cleared.

    File-system errors (a read-only install) leave the cache as it is: numba then falls back to compiling.
    """
    current = source_hash(package_dir)
    stamp = stamp_path(package_dir)
    try:
        if stamp.exists() and stamp.read_text().strip() == current:
            return False
        for d in cache_dirs(package_dir):
            for f in d.iterdir():
                if f.suffix in CACHE_SUFFIXES:
                    f.unlink(missing_ok=True)
        stamp.parent.mkdir(parents=True, exist_ok=True)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(current + "\n")
        tmp.replace(stamp)
    except OSError:
        return False
    return True
