"""Write the way-point samples in tests/data/geo/: one local path, four planning-tool formats.

The local path is the paper's closed path (configs/paper.yaml) moved 5 m east and 3 m north, at
altitudes relative to home, around ArduPilot SITL's default home (Canberra). Each format stores
latitude / longitude to the precision its tool writes (QGC .plan: full double; the text formats:
1e-8 deg, about 1 mm). Run from the repository root: python scripts/make_geo_samples.py
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from pf_offboard.geo import GeoPoint, enu_to_geodetic

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "tests" / "data" / "geo"
HOME = GeoPoint(-35.363261, 149.165230, 584.0)
OFFSET_ENU_M = np.array([5.0, 3.0, 0.0])


def local_path() -> np.ndarray:
    data = yaml.safe_load((ROOT / "pf_offboard" / "configs" / "paper.yaml").read_text())
    return np.array(data["path"]["waypoints"], dtype=float) + OFFSET_ENU_M


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    enu = local_path()
    # horizontal position from the geodesy; altitude relative to home = the local z exactly
    lla = enu_to_geodetic(np.column_stack([enu[:, :2], np.zeros(len(enu))]), HOME)
    rel = enu[:, 2]
    np.savetxt(OUT / "expected_local_enu_m.txt", enu, fmt="%.6f", header="local ENU (m) of the samples' way-points, origin = home")

    items = [{"type": "SimpleItem", "command": 22, "frame": 3, "doJumpId": 1, "autoContinue": True,
              "params": [0, 0, 0, None, HOME.lat_deg, HOME.lon_deg, 2.0], "AMSLAltAboveTerrain": None, "Altitude": 2, "AltitudeMode": 1}]
    items.append({"type": "SimpleItem", "command": 178, "frame": 2, "doJumpId": 2, "autoContinue": True,
                  "params": [1, 1.5, -1, 0, 0, 0, 0]})
    for i, ((la, lo, _), h) in enumerate(zip(lla, rel)):
        items.append({"type": "SimpleItem", "command": 16, "frame": 3, "doJumpId": i + 3, "autoContinue": True,
                      "params": [0, 0, 0, None, float(la), float(lo), float(h)], "AMSLAltAboveTerrain": None,
                      "Altitude": float(h), "AltitudeMode": 1})
    items.append({"type": "SimpleItem", "command": 20, "frame": 2, "doJumpId": len(items) + 1, "autoContinue": True,
                  "params": [0, 0, 0, 0, 0, 0, 0]})
    plan = {"fileType": "Plan", "groundStation": "QGroundControl", "version": 1,
            "geoFence": {"circles": [], "polygons": [], "version": 2},
            "mission": {"cruiseSpeed": 15, "firmwareType": 12, "hoverSpeed": 5, "globalPlanAltitudeMode": 1,
                        "items": items, "plannedHomePosition": [HOME.lat_deg, HOME.lon_deg, HOME.alt_amsl_m],
                        "vehicleType": 2, "version": 2},
            "rallyPoints": {"points": [], "version": 2}}
    (OUT / "mission.plan").write_text(json.dumps(plan, indent=4) + "\n")

    lines = ["QGC WPL 110", f"0\t1\t0\t16\t0\t0\t0\t0\t{HOME.lat_deg:.8f}\t{HOME.lon_deg:.8f}\t{HOME.alt_amsl_m:.6f}\t1"]
    lines.append(f"1\t0\t3\t22\t0\t0\t0\t0\t0.00000000\t0.00000000\t2.000000\t1")
    for i, ((la, lo, _), h) in enumerate(zip(lla, rel), start=2):
        lines.append(f"{i}\t0\t3\t16\t0\t0\t0\t0\t{la:.8f}\t{lo:.8f}\t{h:.6f}\t1")
    (OUT / "mission.waypoints").write_text("\n".join(lines) + "\n")

    rows = ["# the paper path, 5 m east / 3 m north of home; altitude relative to home", "name,lat,lon,alt"]
    rows += [f"wp{i},{la:.8f},{lo:.8f},{h:.3f}" for i, ((la, lo, _), h) in enumerate(zip(lla, rel))]
    (OUT / "mission.csv").write_text("\n".join(rows) + "\n")

    coords = [[round(float(lo), 8), round(float(la), 8), round(float(h), 3)] for (la, lo, _), h in zip(lla, rel)]
    geojson = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"name": "home"}, "geometry": {"type": "Point", "coordinates": [HOME.lon_deg, HOME.lat_deg]}},
        {"type": "Feature", "properties": {"name": "paper path"}, "geometry": {"type": "LineString", "coordinates": coords}},
    ]}
    (OUT / "mission.geojson").write_text(json.dumps(geojson, indent=2) + "\n")

    kml_coords = " ".join(f"{lo:.8f},{la:.8f},{h:.3f}" for (la, lo, _), h in zip(lla, rel))
    (OUT / "mission.kml").write_text(
        '<?xml version="1.0" encoding="UTF-8"?>\n<kml xmlns="http://www.opengis.net/kml/2.2">\n<Document>\n'
        f"<Placemark><name>paper path</name><LineString><altitudeMode>relativeToGround</altitudeMode>"
        f"<coordinates>{kml_coords}</coordinates></LineString></Placemark>\n</Document>\n</kml>\n"
    )


if __name__ == "__main__":
    main()
