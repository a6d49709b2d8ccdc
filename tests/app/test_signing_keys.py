"""Signing key files (``--signing-key``): the three formats, the errors, and app / mock agreement."""

from __future__ import annotations

import hashlib

import pytest
from sitl_mock import signing as mock_signing
from sitl_mock.cli import build_parser, config_from_args, config_to_args
from sitl_mock.config import MockConfigError

from pf_offboard.app import signing
from pf_offboard.app.fly import signing_key_from_args
from pf_offboard.errors import InputError


@pytest.mark.parametrize("module", [signing, mock_signing], ids=["app", "mock"])
def test_key_formats(module) -> None:
    raw = bytes(range(200, 232))  # 32 bytes, not text
    assert module.key_from_bytes(raw) == raw
    assert module.key_from_bytes((raw.hex() + "\n").encode()) == raw  # 64 hex digits
    assert module.key_from_bytes(b"  correct horse battery staple\n") == hashlib.sha256(b"correct horse battery staple").digest()
    # 32 printable characters are a passphrase, not a raw key (a typed key is text)
    assert module.key_from_bytes(b"z" * 32) == hashlib.sha256(b"z" * 32).digest()
    for bad, why in ((b"", "empty"), (b" \n", "empty"), (b"\xff" * 31, "exactly 32 bytes"), (b"x" * 5000, "too large")):
        with pytest.raises(ValueError, match=why):
            module.key_from_bytes(bad)


def test_app_and_mock_read_the_same_key(tmp_path) -> None:
    for content in (b"passphrase", bytes(range(32)), ("ab" * 32).encode()):
        path = tmp_path / "k"
        path.write_bytes(content)
        path.chmod(0o600)
        assert signing.read_key_file(str(path)) == mock_signing.read_key_file(str(path))


def test_bad_key_file_is_one_input_error_naming_the_flag(tmp_path) -> None:
    import argparse

    with pytest.raises(InputError) as err:
        signing_key_from_args(argparse.Namespace(signing_key=str(tmp_path / "missing")))
    assert err.value.field == "--signing-key" and "cannot read" in err.value.reason
    empty = tmp_path / "empty"
    empty.write_bytes(b"")
    empty.chmod(0o600)
    with pytest.raises(InputError, match="empty key file"):
        signing_key_from_args(argparse.Namespace(signing_key=str(empty)))
    assert signing_key_from_args(argparse.Namespace(signing_key=None)) is None


def test_mock_cli_signing_key_round_trips_and_is_validated(tmp_path) -> None:
    key = tmp_path / "key"
    key.write_text("secret key\n")
    key.chmod(0o600)
    config = config_from_args(build_parser().parse_args(["--signing-key", str(key), "--udp-local", "0", "--udp-remote", "none"]))
    assert config.signing_key_file == str(key) and config.signing_key() == hashlib.sha256(b"secret key").digest()
    again = config_from_args(build_parser().parse_args(config_to_args(config)))
    assert again.signing_key_file == str(key)
    with pytest.raises(MockConfigError) as err:
        config_from_args(build_parser().parse_args(["--signing-key", str(tmp_path / "nope")]))
    assert err.value.field == "signing_key_file"


@pytest.mark.parametrize("module", [signing, mock_signing], ids=["app", "mock"])
def test_exact_formats_no_silent_passphrase(module) -> None:
    """63 or 65 hex digits are a mistyped key, never silently hashed as a passphrase; short or
    multi-line passphrases are refused."""
    for bad, why in ((b"a" * 63, "63 hex digits"), (b"0" * 65, "65 hex digits"), (b"deadbeef", "8 hex digits"),
                     (b"short", "at least 8"), (b"two\nlines here", "one line")):
        with pytest.raises(ValueError, match=why):
            module.key_from_bytes(bad)


@pytest.mark.parametrize("module", [signing, mock_signing], ids=["app", "mock"])
def test_key_files_checked_like_ssh_keys(module, tmp_path) -> None:
    """World- or group-readable files are refused (chmod 600 named); FIFOs, devices and directories
    are refused without being read (a FIFO with no writer would block an ordinary open/read)."""
    import os

    key = tmp_path / "key"
    key.write_text("a long enough passphrase\n")
    for mode in (0o644, 0o640, 0o604):
        key.chmod(mode)
        with pytest.raises(ValueError, match="chmod 600"):
            module.read_key_file(str(key))
    key.chmod(0o600)
    assert module.read_key_file(str(key)) == hashlib.sha256(b"a long enough passphrase").digest()
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    for path in (str(fifo), "/dev/zero", "/dev/null", str(tmp_path)):
        with pytest.raises((ValueError, OSError)):
            module.read_key_file(path)


def test_bad_key_files_are_one_line_exit_2(tmp_path) -> None:
    import argparse
    import os

    fifo = tmp_path / "fifo"
    os.mkfifo(fifo, 0o600)
    open_key = tmp_path / "open"
    open_key.write_text("a long enough passphrase")
    open_key.chmod(0o644)
    for path, why in ((fifo, "not a regular file"), (open_key, "too open"), (tmp_path / ("x" * 5000), "cannot read")):
        with pytest.raises(InputError, match=why) as err:
            signing_key_from_args(argparse.Namespace(signing_key=str(path)))
        assert err.value.field == "--signing-key" and "\n" not in str(err.value)


def test_a_wrong_signature_never_advances_the_stream_timestamp() -> None:
    """pymavlink records a stream's timestamp before it compares the signature; with
    verify_signature_first one forged frame (no key, a timestamp far ahead) changes nothing and the
    next genuine frame is accepted."""
    from pymavlink.dialects.v20 import common as mavlink2

    key, wrong = bytes(range(32)), bytes(range(1, 33))

    def sender(k: bytes, timestamp: int) -> mavlink2.MAVLink:
        mav = mavlink2.MAVLink(None, srcSystem=1, srcComponent=1)
        mav.signing.secret_key, mav.signing.sign_outgoing, mav.signing.timestamp = k, True, timestamp
        return mav

    def receiver(fixed: bool) -> mavlink2.MAVLink:
        mav = mavlink2.MAVLink(None, srcSystem=255, srcComponent=190)
        mav.robust_parsing = True
        mav.signing.secret_key, mav.signing.timestamp = key, 10**9
        if fixed:
            signing.verify_signature_first(mav)
        return mav

    hb = mavlink2.MAVLink_heartbeat_message(2, 12, 0, 0, 4, 3)
    forged = hb.pack(sender(wrong, 10**13))
    genuine = hb.pack(sender(key, 10**9 + 100))
    for fixed in (False, True):
        rx = receiver(fixed)
        got = [m.get_type() for m in (rx.parse_buffer(forged) or []) + (rx.parse_buffer(genuine) or [])]
        assert ("HEARTBEAT" in got) is fixed, (fixed, got)  # unfixed pymavlink: the genuine frame is "old"
