"""Reading a file the user named (a config, a way-point file, a flight log): bounded and never blocking.

Only regular files are read: a FIFO, a device (``/dev/zero``, a serial port), a socket or a
directory is refused before a byte is read (checked on the open descriptor, opened non-blocking,
so nothing hangs and nothing grows without bound); so is a file larger than the caller's limit.
Every failure is a :class:`ValueError` with a one-line reason (the caller names the flag or file).
"""

from __future__ import annotations

import os
import stat
import zlib

_KINDS = ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))  # fmt: skip


def _size_text(n: int) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.1f} MiB" if n >= 2**20 else f"{n / 1024:.0f} kB"


def _open_checked(path: str | os.PathLike[str], max_bytes: int) -> int:
    """A descriptor of the regular file ``path`` (opened non-blocking) if it is at most ``max_bytes`` long."""
    try:
        fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise ValueError(f"cannot read: {exc.strerror or exc}") from None
    except (ValueError, TypeError) as exc:  # an embedded NUL, a name not encodable
        raise ValueError(f"not a usable file name ({exc})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = next((name for test, name in _KINDS if test(st.st_mode)), "not a regular file")
            raise ValueError(f"{kind}, not a regular file: not read")
        if st.st_size > max_bytes:
            raise ValueError(f"{_size_text(st.st_size)}: larger than the {_size_text(max_bytes)} this input may be")
    except BaseException:
        os.close(fd)
        raise
    return fd


def check_bounded(path: str | os.PathLike[str], max_bytes: int) -> None:
    """Raise as :func:`read_bounded` would, without reading: for a file a library then opens
    itself (pymavlink, pyulog), so a FIFO, a device or a huge file never reaches it."""
    os.close(_open_checked(path, max_bytes))


def read_bounded(path: str | os.PathLike[str], max_bytes: int) -> bytes:
    """The whole content of the regular file ``path`` if it is at most ``max_bytes`` long."""
    fd = _open_checked(path, max_bytes)
    try:
        chunks: list[bytes] = []
        size = 0
        while size <= max_bytes:
            try:
                chunk = os.read(fd, min(1 << 20, max_bytes + 1 - size))
            except OSError as exc:
                raise ValueError(f"cannot read: {exc.strerror or exc}") from None
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > max_bytes:  # it grew while we read it
            raise ValueError(f"larger than the {_size_text(max_bytes)} this input may be")
        return b"".join(chunks)
    finally:
        os.close(fd)


def gunzip_bounded(data: bytes, max_bytes: int) -> bytes:
    """Decompress gzip ``data`` to at most ``max_bytes`` (a decompression bomb is refused)."""
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        out = d.decompress(data, max_bytes + 1)
    except zlib.error as exc:
        raise ValueError(f"not a valid gzip file: {exc}") from None
    if len(out) > max_bytes or d.unconsumed_tail:
        raise ValueError(f"decompresses to more than {_size_text(max_bytes)}")
    if not d.eof:
        raise ValueError("not a valid gzip file: truncated")
    return out
