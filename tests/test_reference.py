"""The reference pages are generated from the code: the committed ones must match it."""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _generator():
    spec = importlib.util.spec_from_file_location("gen_reference", ROOT / "scripts" / "gen_reference.py")
    module = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_committed_reference_pages_match_the_code() -> None:
    gen = _generator()
    for name, make in gen.PAGES.items():
        committed = (ROOT / "docs" / "reference" / name).read_text(encoding="utf-8")
        assert committed == make(), f"docs/reference/{name} is stale: run python scripts/gen_reference.py"


def test_config_reference_lists_every_field_the_loader_reads_with_its_range() -> None:
    from pf_offboard.config import FlightConfig
    from pf_offboard.safety import SafetyConfig

    fields = {f.name: f for f in _generator().config_fields()}
    for name in FlightConfig.__dataclass_fields__:
        assert f"flight.{name}" in fields
    for name in ("min_altitude_m", "max_tilt_deg", "heartbeat_timeout_s"):
        assert f"safety.{name}" in fields
    takeoff = fields["flight.takeoff_altitude_m"]
    assert (takeoff.default, takeoff.lo, takeoff.hi) == (FlightConfig().takeoff_altitude_m, 0.3, 100.0)
    assert fields["flight.output_mode"].choices == ("acceleration", "attitude", "rates")
    assert SafetyConfig().min_altitude_m == fields["safety.min_altitude_m"].default
