"""Lines of a stream as they arrive: a CSV file that grows (followed like ``tail -F``) or standard input.

The reader of ``wingopt identify --follow FILE`` / ``--data -``
(:func:`wingopt.workflows.stream.follow`): complete lines only, in bounded memory, stopping on the
end of standard input, an idle timeout or a stop flag set by a signal handler.
"""

from __future__ import annotations

import logging
import os
import select
import sys
import time

from wingopt.errors import DataFileError

__all__ = ["LineSource", "MAX_LINE_BYTES"]

log = logging.getLogger(__name__)


MAX_LINE_BYTES = 1 << 20
"""Longest line a stream may send (1 MiB: a row of a few thousand sensors); longer is refused."""


class LineSource:
    """Complete lines of a growing file or of standard input; stops on EOF (stdin), idle or a signal.

    A followed file is watched like ``tail -F``: when it shrinks (truncated and rewritten) it is
    read again from its start, when its name points to another file (rotated: renamed and
    recreated, or deleted and recreated) the rest of the old file is read, then the new one from
    its start; each is said in a log line and counted (``restarts``). Memory is bounded: a line
    longer than :data:`MAX_LINE_BYTES` ends the stream with a :class:`DataFileError`.
    """

    def __init__(self, path: str | None, poll: float, idle: float | None, stop: dict) -> None:
        self.path, self.poll, self.idle, self.stop = path, poll, idle, stop
        self.reason = None
        self.restarts: list[str] = []
        self.line_no = 0
        self._reopen = False  # the next line starts a new file (its header may come again)

    @property
    def name(self) -> str:
        return self.path or "<stdin>"

    def take_restart(self) -> bool:
        """Whether the lines now come from a new file (truncated or rotated) since the last call."""
        r, self._reopen = self._reopen, False
        return r

    def _restart(self, what: str) -> None:
        self.restarts.append(what)
        self._reopen = True
        log.warning("%s %s: reading it from its start", self.path, what)

    def __iter__(self):
        buf = b""
        last = time.monotonic()
        fh = None
        ino = None
        fd = None if self.path else sys.stdin.fileno()
        gone = False
        try:
            while True:
                if self.stop.get("signal"):
                    self.reason = self.stop["signal"]
                    return
                chunk = b""
                if fd is None:
                    if fh is None:
                        fh, ino = self._open()
                    chunk = fh.read(65536) if fh is not None else b""
                    if not chunk and fh is not None:
                        # At the end of the file: has it been truncated, rotated or deleted?
                        try:
                            st = os.stat(self.path)
                        except FileNotFoundError:
                            if not gone:
                                log.warning("%s was deleted: waiting for it to come back", self.path)
                            gone = True
                            st = None
                        except OSError:
                            st = None
                        if st is not None:
                            gone = False
                            if (st.st_ino, st.st_dev) != ino:
                                if buf:  # the old file's last line, without its newline
                                    yield from self._emit(buf)
                                    buf = b""
                                fh.close()
                                fh, ino = self._open()
                                self._restart("was replaced by a new file (rotated)")
                                last = time.monotonic()
                                continue
                            if st.st_size < fh.tell():
                                fh.seek(0)
                                buf = b""
                                self._restart("was truncated")
                                last = time.monotonic()
                                continue
                else:
                    ready, _, _ = select.select([fd], [], [], self.poll)
                    if ready:
                        chunk = os.read(fd, 65536)
                        if not chunk:
                            if buf:
                                yield from self._emit(buf)
                            self.reason = "end of input"
                            return
                if chunk:
                    buf += chunk
                    *lines, buf = buf.split(b"\n")
                    if len(buf) > MAX_LINE_BYTES:
                        raise DataFileError(
                            f"{self.name}:{self.line_no + len(lines) + 1}: a line longer than "
                            f"{MAX_LINE_BYTES // 1024} kB without a newline: not a CSV of sensor readings"
                        )
                    if lines:
                        last = time.monotonic()
                    for raw in lines:
                        yield from self._emit(raw)
                    continue
                if self.idle is not None and time.monotonic() - last > self.idle:
                    self.reason = f"idle for {self.idle:g} s"
                    return
                if fd is None:
                    time.sleep(self.poll)
        finally:
            if fh is not None:
                fh.close()

    def _open(self):
        try:
            fh = open(self.path, "rb")
        except FileNotFoundError:
            return None, None
        except IsADirectoryError:
            raise DataFileError(f"follow = {self.path!r}: is a directory, expected a CSV file") from None
        except OSError as exc:
            raise DataFileError(f"follow = {self.path!r}: cannot read it ({exc.strerror})") from None
        st = os.fstat(fh.fileno())
        return fh, (st.st_ino, st.st_dev)

    def _emit(self, raw: bytes):
        self.line_no += 1
        if len(raw) > MAX_LINE_BYTES:
            raise DataFileError(
                f"{self.name}:{self.line_no}: a line longer than {MAX_LINE_BYTES // 1024} kB: "
                "not a CSV of sensor readings"
            )
        try:
            yield raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            raise DataFileError(f"{self.name}:{self.line_no}: not a text (UTF-8) CSV stream") from None
