"""MAVLink 2 signing keys from a key file (the same formats the app and ``sitl-mock`` read).

A copy of ``pf_offboard/app/signing.py``: the mock stands in for an autopilot and imports nothing
from the app (tests/sitl_mock/test_mock_signing.py checks the two agree).

A key file holds one of (checked in this order):

1. exactly 32 bytes that are not all printable text: the raw secret key;
2. 64 hexadecimal digits (surrounding whitespace ignored): the key in hex, as printed by
   ``xxd -p -c 32`` or stored by QGroundControl;
3. any other non-empty text: a passphrase, hashed with SHA-256 (surrounding whitespace
   ignored) — what MAVProxy's ``signing setup PASSPHRASE`` does, so the same passphrase gives
   the same key there.

The key never leaves this machine except inside SETUP_SIGNING, which the user sends on purpose.
"""

from __future__ import annotations

import hashlib
import string

KEY_BYTES = 32
# Files larger than this are not key files (a mistyped path to a log or an image).
MAX_KEY_FILE_BYTES = 4096
_HEX = frozenset(string.hexdigits)
_PRINTABLE = frozenset(string.printable.encode())


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
    if len(text) == 2 * KEY_BYTES and all(c in _HEX for c in text):
        return bytes.fromhex(text)
    return hashlib.sha256(text.encode("utf-8")).digest()


def read_key_file(path: str) -> bytes:
    """Read and interpret a key file; OSError / ValueError(reason) on failure."""
    with open(path, "rb") as fh:
        data = fh.read(MAX_KEY_FILE_BYTES + 1)
    return key_from_bytes(data)
