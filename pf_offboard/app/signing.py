"""MAVLink 2 signing: key files (the same formats the app and ``sitl-mock`` read) and a parser
that checks a frame's signature before it believes the frame's timestamp.

A key file is checked like an ssh private key: it must be a regular file (a FIFO, a device or a
directory is refused without being read, so nothing hangs), readable by its owner only (no group
or other permission bits: ``chmod 600 FILE``), and hold exactly one of:

1. 32 bytes that are not all printable text: the raw secret key;
2. exactly 64 hexadecimal digits (surrounding whitespace ignored): the key in hex, as printed by
   ``xxd -p -c 32`` or stored by QGroundControl. Text made only of hex digits but of another
   length (63, 65 ...) is refused: it is a mistyped key, not a passphrase;
3. a passphrase: one line of at least 8 printable characters (surrounding whitespace ignored),
   hashed with SHA-256 — what MAVProxy's ``signing setup PASSPHRASE`` does, so the same
   passphrase gives the same key there.

The key never leaves this machine except inside SETUP_SIGNING, which the user sends on purpose.
"""

from __future__ import annotations

import hashlib
import os
import stat
import string
from typing import Any

KEY_BYTES = 32
# Files larger than this are not key files (a mistyped path to a log or an image).
MAX_KEY_FILE_BYTES = 4096
MIN_PASSPHRASE_CHARS = 8
_HEX = frozenset(string.hexdigits)
_PRINTABLE = frozenset(string.printable.encode())
_TEXT = frozenset(string.printable) - frozenset("\r\n\x0b\x0c")


def key_from_bytes(data: bytes) -> bytes:
    """The 32-byte secret key a key file's content stands for; ValueError(reason) if none."""
    if len(data) > MAX_KEY_FILE_BYTES:
        raise ValueError(f"{len(data)} bytes is too large for a key file (32 raw bytes, 64 hex digits or a passphrase)")
    if len(data) == KEY_BYTES and not all(b in _PRINTABLE for b in data):
        return bytes(data)
    try:
        text = data.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise ValueError(f"{len(data)} bytes of binary data: a raw key must be exactly {KEY_BYTES} bytes") from None
    if not text:
        raise ValueError("empty key file")
    if all(c in _HEX for c in text):
        if len(text) == 2 * KEY_BYTES:
            return bytes.fromhex(text)
        raise ValueError(f"{len(text)} hex digits: a hex key has exactly {2 * KEY_BYTES} (a passphrase must not be all hex digits)")
    if not all(c in _TEXT for c in text):
        raise ValueError("a passphrase must be one line of printable text")
    if len(text) < MIN_PASSPHRASE_CHARS:
        raise ValueError(f"passphrase of {len(text)} characters: at least {MIN_PASSPHRASE_CHARS} are needed")
    return hashlib.sha256(text.encode("utf-8")).digest()


def read_key_file(path: str) -> bytes:
    """Read and interpret a key file; OSError / ValueError(reason) on failure. Never blocks: the
    file is opened non-blocking and refused unless it is a regular file (checked on the open
    descriptor, so a file swapped for a FIFO after a check cannot hang us)."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError("not a regular file (a FIFO, device or directory is never read as a key)")
        if st.st_mode & 0o077:
            raise ValueError(f"permissions {stat.S_IMODE(st.st_mode):04o} are too open: a key must be readable by its owner only (chmod 600)")
        chunks: list[bytes] = []
        size = 0
        while size <= MAX_KEY_FILE_BYTES:
            chunk = os.read(fd, MAX_KEY_FILE_BYTES + 1 - size)
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    finally:
        os.close(fd)
    return key_from_bytes(b"".join(chunks))


def verify_signature_first(mav: Any) -> None:
    """Make ``mav`` (a pymavlink ``MAVLink``) check a signed frame's signature *before* it records
    the frame's timestamp for its stream.

    pymavlink's ``MAVLink.check_signature`` (2.4.x) stores the stream's timestamp, then compares the
    signature: one frame with a wrong signature (no key needed) and a timestamp far in the future
    makes every later genuine frame of that stream "old" and refused — anyone can switch the link
    off. Here the signature is compared first; only a frame signed with our key reaches pymavlink's
    own timestamp check (which then records it). Upstream fix: in ``check_signature``, move
    ``self.signing.stream_timestamps[stream_key] = timestamp`` after the ``sig1 != sig2`` test.
    """
    original = mav.check_signature

    def check_signature(msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        key = mav.signing.secret_key
        if key is None or len(msgbuf) < 13:
            return False
        h = hashlib.sha256()
        h.update(key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            return False
        return bool(original(msgbuf, src_system, src_component))

    mav.check_signature = check_signature
