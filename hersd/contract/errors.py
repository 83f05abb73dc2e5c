"""The errors every layer raises for bad input (config fields, schedules, study storages) and for a full disk."""

from __future__ import annotations

import errno
import shutil
from pathlib import Path

FULL_DISK_ERRNOS = (errno.ENOSPC, errno.EDQUOT)  # no space left on the device; the user's quota used up


class ConfigError(ValueError):
    """A configuration value is out of range; the message is one line for the user."""


class DiskFullError(RuntimeError):
    """A write found its device full; the message is one line naming the file, the bytes the write needed
    (``needed``, None where unknown) and those free, then what to do (``then``)."""

    def __init__(self, path: str | Path, needed: int | None, then: str = "free some and run the same command again"):
        self.path, self.needed = Path(path), needed
        free = free_bytes(self.path)
        shown_free = "" if free is None else f", {_megabytes(free)} free"
        need = f"needs {_megabytes(needed)}" if needed is not None else "needs more space"
        super().__init__(f"no space left on the device of {self.path}: writing it {need}{shown_free}; {then}")


def full_disk(err: BaseException) -> bool:
    """Whether ``err``, or an error it was raised from or while handling (torch wraps a write's OSError in a
    RuntimeError), is a full disk (:data:`FULL_DISK_ERRNOS`)."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, OSError) and err.errno in FULL_DISK_ERRNOS:
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def free_bytes(path: Path) -> int | None:
    """Bytes free to this user on the device of ``path`` (or of its nearest existing folder); None if unknown."""
    for folder in (path, *path.parents):
        try:
            return shutil.disk_usage(folder).free
        except OSError:
            continue
    return None


def _megabytes(size: int) -> str:
    return f"{size / 2**20:.1f} MB" if size >= 2**20 / 10 else f"{size} bytes"
