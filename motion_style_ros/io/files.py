"""Reading a file a user names, bounded: a regular file only (no FIFO, device or directory), no larger
than its kind's limit, and read within a time limit, so that no path in a parameter or on a command
line can hang a process or fill its memory.

The limits are per kind (:data:`LIMITS_MB`); a user raises one with an environment variable
``MOTION_STYLE_MAX_<KIND>_MB`` (e.g. ``MOTION_STYLE_MAX_BVH_MB=512``), and the read time limit with
``MOTION_STYLE_READ_TIMEOUT_S``. Every refusal is a one-line :class:`MotionStyleError` naming the
path and the reason.
"""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

from motion_style_ros.errors import MotionStyleError

# The largest file of each kind, in MiB: several times the largest real one (a 10-minute BVH at
# 120 Hz is about 30 MiB; the shipped ONNX models are under 20 MiB).
LIMITS_MB = {"bvh": 256, "model": 1024, "card": 16, "style bank": 64, "layout": 4, "urdf": 64,
             "body map": 4, "arrays": 1024}
READ_TIMEOUT_S = 30.0


def _env_name(kind: str) -> str:
    return f"MOTION_STYLE_MAX_{kind.upper().replace(' ', '_')}_MB"


def limit_mb(kind: str) -> float:
    """The size limit of ``kind`` in MiB, from its environment variable or :data:`LIMITS_MB`."""
    raw = os.environ.get(_env_name(kind), "")
    try:
        return float(raw) if raw else LIMITS_MB[kind]
    except ValueError:
        raise MotionStyleError(f"{_env_name(kind)}={raw!r} is not a number of MiB") from None


def check(path: str | Path, kind: str) -> Path:
    """``path`` as a Path if it names a regular file within ``kind``'s limit, else a one-line error.

    Looks only at the file's metadata: it never opens a FIFO or a device, so it cannot block."""
    path = Path(path)
    try:
        info = path.stat()
    except OSError as e:
        raise MotionStyleError(f"{path}: cannot read ({e.strerror or e})") from None
    if not stat.S_ISREG(info.st_mode):
        what = ("a directory" if stat.S_ISDIR(info.st_mode) else "a FIFO" if stat.S_ISFIFO(info.st_mode)
                else "a device" if stat.S_ISCHR(info.st_mode) or stat.S_ISBLK(info.st_mode) else "a socket"
                if stat.S_ISSOCK(info.st_mode) else "not a regular file")
        raise MotionStyleError(f"{path}: is {what}; a {kind} must be a regular file")
    limit = limit_mb(kind)
    if info.st_size > limit * 2**20:
        raise MotionStyleError(
            f"{path}: {info.st_size / 2**20:.1f} MiB is over the {limit:g} MiB limit for a {kind} "
            f"(raise it with {_env_name(kind)})")
    return path


def read_bytes(path: str | Path, kind: str, timeout: float | None = None) -> bytes:
    """The bytes of a checked file (:func:`check`), read on a worker within ``timeout`` seconds
    (``MOTION_STYLE_READ_TIMEOUT_S``, else :data:`READ_TIMEOUT_S`); at most the limit is read even if
    the file grows meanwhile."""
    path = check(path, kind)
    limit = int(limit_mb(kind) * 2**20)
    if timeout is None:
        timeout = float(os.environ.get("MOTION_STYLE_READ_TIMEOUT_S", READ_TIMEOUT_S))
    result: list = []

    def read() -> None:
        try:
            with open(path, "rb") as f:
                result.append(f.read(limit + 1))
        except OSError as e:
            result.append(e)

    worker = threading.Thread(target=read, name=f"read {path.name}", daemon=True)
    worker.start()
    worker.join(timeout)
    if not result:
        raise MotionStyleError(f"{path}: not read within {timeout:g} s (a slow or hung file system?)")
    data = result[0]
    if isinstance(data, OSError):
        raise MotionStyleError(f"{path}: cannot read ({data.strerror or data})")
    if len(data) > limit:
        raise MotionStyleError(f"{path}: grew over the {limit / 2**20:g} MiB limit for a {kind} while read")
    return data


def read_text(path: str | Path, kind: str, timeout: float | None = None) -> str:
    """:func:`read_bytes` decoded as UTF-8 (undecodable bytes replaced: the parser names the problem)."""
    return read_bytes(path, kind, timeout).decode("utf-8", errors="replace")
