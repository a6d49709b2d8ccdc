"""Fly a QGroundControl mission (.plan) as one smooth path through its way-points.

The way-points are latitude / longitude: they are placed in the vehicle's local frame from its own
origin (EKF origin / home) before anything is sent.

    python fly_qgc_plan.py [ENDPOINT] [PLAN]      # default: udp://:14540 mission.plan
"""
import asyncio
import sys
from pathlib import Path

import pf_offboard

HERE = Path(__file__).resolve().parent


async def main(endpoint: str, plan: str) -> None:
    async with pf_offboard.connect(endpoint) as vehicle:
        await vehicle.takeoff(2.0)
        result = await vehicle.follow(plan, speed=1.0)  # an open path: ends at its last way-point
        print(result.reason, f"cross-track RMS {result.whole_cross_track_rms_m:.3f} m (convergence included)")
        await vehicle.hand_back("land")


asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udp://:14540", sys.argv[2] if len(sys.argv) > 2 else str(HERE / "mission.plan")))
