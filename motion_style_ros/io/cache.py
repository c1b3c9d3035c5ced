"""An on-disk cache of numpy arrays derived from source files, so runs do not re-parse datasets.

Entries live in ``~/.cache/motion_style_ros/`` (or ``$MOTION_STYLE_CACHE``), one ``.npz`` per entry,
stored with a key computed from the names, sizes and modification times of the files they came
from: an entry whose sources changed reads as missing and is rebuilt by its owner. Writes go to a
temporary file that is renamed into place, so concurrent builders and interrupted runs never leave a
half-written entry behind.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from motion_style_ros.errors import MotionStyleError


def cache_dir() -> Path:
    return Path(os.environ.get("MOTION_STYLE_CACHE") or Path.home() / ".cache" / "motion_style_ros")


def source_key(paths: Iterable[Path]) -> str:
    """A digest of the files' names, sizes and mtimes: cheap to compute, changes when any file does."""
    digest = hashlib.sha256()
    for path in sorted(paths):
        st = path.stat()
        digest.update(f"{path.name}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return digest.hexdigest()


def entry_path(name: str) -> Path:
    return cache_dir() / f"{name}.npz"


def load(name: str, key: str) -> dict[str, np.ndarray] | None:
    """The arrays stored under ``name``, or None when the entry is missing, stale or unreadable."""
    try:
        with np.load(entry_path(name)) as npz:
            if "key" not in npz.files or str(npz["key"]) != key:
                return None
            return {k: npz[k] for k in npz.files if k != "key"}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return None


def save(name: str, key: str, arrays: dict[str, np.ndarray]) -> Path:
    """Store ``arrays`` under ``name`` atomically (plain arrays only: loading never unpickles)."""
    folder = cache_dir()
    path = entry_path(name)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{name}.", suffix=".tmp")
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez(f, key=np.array(key), **arrays)
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    except OSError as e:
        raise MotionStyleError(
            f"{path}: cannot write the cache ({e.strerror or e}); "
            "point MOTION_STYLE_CACHE at a writable folder"
        ) from None
    return path
