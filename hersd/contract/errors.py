"""The errors every layer raises for bad input (config fields, schedules, study storages) and for a full disk."""

from __future__ import annotations

import errno
import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

FULL_DISK_ERRNOS = (errno.ENOSPC, errno.EDQUOT)  # no space left on the device; the user's quota used up


class ConfigError(ValueError):
    """A configuration value is out of range; the message is one line for the user."""


class DiskFullError(RuntimeError):
    """A write found its device full; the message is one line naming the file, the bytes the write needed
    (``needed``, None where unknown) and those free, then what to do (``then``)."""

    def __init__(self, path: str | Path, needed: int | None, then: str = "free some and run the same command again"):
        self.path, self.needed, self.then = Path(path), needed, then
        free = free_bytes(self.path)
        shown_free = "" if free is None else f", {_size(free)} free"
        need = f"needs {_size(needed)}" if needed is not None else "needs more space"
        super().__init__(f"no space left on the device of {self.path}: writing it {need}{shown_free}; {then}")

    def __reduce__(self):  # pickled by its arguments, not its message: it crosses from worker processes
        return type(self), (self.path, self.needed, self.then)


def full_disk(err: BaseException) -> bool:
    """Whether ``err``, or an error it was raised from or while handling (torch wraps a write's OSError in a
    RuntimeError), is a full disk (:data:`FULL_DISK_ERRNOS`, or a :class:`DiskFullError`, which keeps no OSError
    once it crossed from another process)."""
    return any(isinstance(link, DiskFullError) or isinstance(link, OSError) and link.errno in FULL_DISK_ERRNOS
               for link in _chain(err))


def interrupted(err: BaseException) -> bool:
    """Whether ``err`` is, or was raised while handling, a Ctrl-C (KeyboardInterrupt): torch.save interrupted in
    the middle of its write ends in its zip writer's own RuntimeError, the Ctrl-C only its context."""
    return any(isinstance(link, KeyboardInterrupt) for link in _chain(err))


@contextmanager
def sigterm_as_ctrl_c() -> Iterator[None]:
    """Within the block (or the function it decorates), SIGTERM (``kill PID``, a supervisor stopping the command)
    is a Ctrl-C: a KeyboardInterrupt, so the command's one line, exit 130 and clean-up hold for it too. The
    handler before it is restored on the way out (a command's ``main`` called in another program leaves it as it
    was). A SIGTERM that follows while the first is handled is ignored: the clean-up it started is not cut short
    (a supervisor that signals a process group reaches the command and its workers, and a command passes it on to
    workers too). Only in the main thread, where Python runs signal handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _interrupt(signum: int, frame: object) -> None:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _chain(err: BaseException | None) -> Iterator[BaseException]:
    """``err`` and the errors it was raised from or while handling, each once."""
    seen: set[int] = set()
    while err is not None and id(err) not in seen:
        yield err
        seen.add(id(err))
        err = err.__cause__ or err.__context__


def _device(path: Path) -> os.statvfs_result | None:
    """The file system of ``path`` (or of its nearest existing folder); None if unknown."""
    for folder in (path, *path.parents):
        try:
            return os.statvfs(folder)
        except OSError:
            continue
    return None


def free_bytes(path: Path) -> int | None:
    """Bytes free to this user on the device of ``path`` (or of its nearest existing folder); None if unknown."""
    device = _device(Path(path))
    return None if device is None else device.f_bavail * device.f_frsize


def block_bytes(path: str | Path) -> int | None:
    """The bytes a new folder takes on the device of ``path``: one block; None if unknown."""
    device = _device(Path(path))
    return None if device is None else device.f_bsize


def _size(size: int) -> str:
    """``512 bytes``, ``108.3 KB``, ``12.0 MB``, ``75.3 GB`` (binary units)."""
    for unit, scale in (("GB", 2**30), ("MB", 2**20), ("KB", 2**10)):
        if size >= scale:
            return f"{size / scale:.1f} {unit}"
    return f"{size} bytes"
