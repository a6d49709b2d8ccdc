"""The reference pages are generated from the code: the committed ones must match it."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_committed_reference_pages_match_the_code(script) -> None:
    gen = script("gen_reference")
    for name, make in gen.PAGES.items():
        committed = (ROOT / "docs" / "reference" / name).read_text(encoding="utf-8")
        assert committed == make(), f"docs/reference/{name} is stale: run python scripts/gen_reference.py"


def test_config_reference_lists_every_field_the_loader_reads_with_its_range(script) -> None:
    from pf_offboard.config import FlightConfig
    from pf_offboard.safety import SafetyConfig

    fields = {f.name: f for f in script("gen_reference").config_fields()}
    for name in FlightConfig.__dataclass_fields__:
        assert f"flight.{name}" in fields
    for name in ("min_altitude_m", "max_tilt_deg", "heartbeat_timeout_s"):
        assert f"safety.{name}" in fields
    takeoff = fields["flight.takeoff_altitude_m"]
    assert (takeoff.default, takeoff.lo, takeoff.hi) == (FlightConfig().takeoff_altitude_m, 0.3, 100.0)
    assert fields["flight.output_mode"].choices == ("acceleration", "attitude", "rates")
    assert SafetyConfig().min_altitude_m == fields["safety.min_altitude_m"].default
