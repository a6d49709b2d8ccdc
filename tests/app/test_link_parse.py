"""Endpoint parsing: every malformed --connect is one InputError naming the flag."""

import pytest

from pf_offboard.app.link import Endpoint, parse_endpoint
from pf_offboard.errors import InputError


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("udpin:0.0.0.0:14540", Endpoint("udpin", "0.0.0.0", 14540)),
        ("udpout:127.0.0.1:14580", Endpoint("udpout", "127.0.0.1", 14580)),
        ("tcp:localhost:5760", Endpoint("tcp", "localhost", 5760)),
        ("serial:/dev/ttyACM0:921600", Endpoint("serial", "/dev/ttyACM0", 921600)),
    ],
)
def test_valid_endpoints(text: str, expected: Endpoint) -> None:
    ep = parse_endpoint(text)
    assert ep == expected
    assert str(ep) == text


def test_mavutil_urls() -> None:
    assert parse_endpoint("udpin:0.0.0.0:14540").mavutil_url() == "udpin:0.0.0.0:14540"
    assert parse_endpoint("serial:/dev/ttyUSB0:57600").mavutil_url() == "/dev/ttyUSB0"


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "KIND:ADDRESS:PORT"),
        ("14540", "KIND:ADDRESS:PORT"),
        ("udp:127.0.0.1:14540", "unknown endpoint kind 'udp'"),
        ("udpin:14540", "expected udpin:HOST:PORT"),
        ("udpin:127.0.0.1:", "expected udpin:HOST:PORT"),
        ("tcp:127.0.0.1:port", "port 'port' is not a positive integer"),
        ("tcp:127.0.0.1:0", "outside 1..65535"),
        ("tcp:127.0.0.1:70000", "outside 1..65535"),
        ("tcp:bad host:5760", "not a host name"),
        ("serial:/dev/ttyACM0:fast", "baud rate 'fast'"),
        ("serial:/dev/ttyACM0:0", "baud rate must be positive"),
    ],
)
def test_malformed_endpoints(text: str, fragment: str) -> None:
    with pytest.raises(InputError) as info:
        parse_endpoint(text)
    assert info.value.field == "--connect"
    assert fragment in info.value.reason
