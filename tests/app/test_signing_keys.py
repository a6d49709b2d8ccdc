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
    assert module.key_from_bytes(b"a" * 32) == hashlib.sha256(b"a" * 32).digest()
    for bad, why in ((b"", "empty"), (b" \n", "empty"), (b"\xff" * 31, "exactly 32 bytes"), (b"x" * 5000, "too large")):
        with pytest.raises(ValueError, match=why):
            module.key_from_bytes(bad)


def test_app_and_mock_read_the_same_key(tmp_path) -> None:
    for content in (b"passphrase", bytes(range(32)), ("ab" * 32).encode()):
        path = tmp_path / "k"
        path.write_bytes(content)
        assert signing.read_key_file(str(path)) == mock_signing.read_key_file(str(path))


def test_bad_key_file_is_one_input_error_naming_the_flag(tmp_path) -> None:
    import argparse

    with pytest.raises(InputError) as err:
        signing_key_from_args(argparse.Namespace(signing_key=str(tmp_path / "missing")))
    assert err.value.field == "--signing-key" and "cannot read" in err.value.reason
    empty = tmp_path / "empty"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty key file"):
        signing_key_from_args(argparse.Namespace(signing_key=str(empty)))
    assert signing_key_from_args(argparse.Namespace(signing_key=None)) is None


def test_mock_cli_signing_key_round_trips_and_is_validated(tmp_path) -> None:
    key = tmp_path / "key"
    key.write_text("secret\n")
    config = config_from_args(build_parser().parse_args(["--signing-key", str(key), "--udp-local", "0", "--udp-remote", "none"]))
    assert config.signing_key_file == str(key) and config.signing_key() == hashlib.sha256(b"secret").digest()
    again = config_from_args(build_parser().parse_args(config_to_args(config)))
    assert again.signing_key_file == str(key)
    with pytest.raises(MockConfigError) as err:
        config_from_args(build_parser().parse_args(["--signing-key", str(tmp_path / "nope")]))
    assert err.value.field == "signing_key_file"
