"""Pseudo-terminals that stand in for USB serial adapters, with unplug / replug.

The emulator owns the master side and keeps its own slave descriptor open, so the master never sees
EIO while no client is attached (like a UART with the cable in but nobody listening). Clients open
``path``: a stable symlink (like ``/dev/serial/by-id/...``) that is re-pointed at the new
``/dev/pts/N`` on replug, so a driver reconnecting by name finds the device again.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import tempfile
import threading
import tty
from pathlib import Path


class PtyPort:
    """One emulated serial device. ``write`` never blocks (bytes are lost if nobody reads, as on a
    real UART); ``read`` waits up to ``timeout`` seconds."""

    def __init__(self, link: str | os.PathLike[str] | None = None, name: str = "navdeck") -> None:
        self._own_dir: Path | None = None
        if link is None:
            self._own_dir = Path(tempfile.mkdtemp(prefix="navdeck-pty-"))
            link = self._own_dir / name
        self.link = Path(link)
        self._master: int | None = None
        self._slave: int | None = None
        self.slave_name = ""
        self._lock = threading.Lock()
        self.bytes_dropped = 0
        self.plug()

    @property
    def path(self) -> str:
        """What clients open: the stable symlink."""
        return str(self.link)

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def plug(self) -> None:
        """Create a new pty pair and point ``link`` at its slave."""
        with self._lock:
            if self._master is not None:
                return
            master, slave = os.openpty()
            tty.setraw(slave)  # no echo, no line discipline: bytes pass unchanged
            os.set_blocking(master, False)
            self.slave_name = os.ttyname(slave)
            tmp = self.link.with_name(self.link.name + ".tmp")
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()
            self.link.parent.mkdir(parents=True, exist_ok=True)
            os.symlink(self.slave_name, tmp)
            os.replace(tmp, self.link)
            self._master, self._slave = master, slave

    def unplug(self) -> None:
        """Close both sides and remove the link: clients see EIO, reopening fails until ``plug``."""
        with self._lock:
            master, slave = self._master, self._slave
            self._master = self._slave = None
            with contextlib.suppress(FileNotFoundError):
                self.link.unlink()
            for fd in (master, slave):
                if fd is not None:
                    with contextlib.suppress(OSError):
                        os.close(fd)

    def close(self) -> None:
        """Unplug for good (and remove the temporary directory holding the link, if ours)."""
        self.unplug()
        if self._own_dir is not None:
            with contextlib.suppress(OSError):
                self._own_dir.rmdir()

    def read(self, timeout: float) -> bytes:
        """Bytes the client wrote (empty on timeout or while unplugged)."""
        fd = self._master
        if fd is None:
            return b""
        try:
            ready, _, _ = select.select([fd], [], [], max(timeout, 0.0))
            if not ready:
                return b""
            return os.read(fd, 4096)
        except (OSError, ValueError):
            return b""

    def write(self, data: bytes) -> int:
        """Write what fits into the pty buffer; the rest is dropped and counted."""
        fd = self._master
        if fd is None:
            return 0
        try:
            n = os.write(fd, data)
        except BlockingIOError:
            n = 0
        except OSError as exc:
            if exc.errno not in (errno.EIO, errno.EBADF):
                raise
            n = 0
        self.bytes_dropped += len(data) - n
        return n
