"""Two paths in one connection: a loop, then a climb along a line, each handed back in hold.

    python two_paths.py [ENDPOINT]
"""
import asyncio
import sys

import pf_offboard
from pf_offboard import Path

LOOP = Path.from_waypoints([[0, -1.5, 2], [1.5, 0, 2.5], [0, 1.5, 2], [-1.5, 0, 1.5]], closed=True)
LINE = Path.from_waypoints([[0, -1.5, 2], [0, 0, 2.5], [0, 1.5, 3]], closed=False)


async def main(endpoint: str) -> None:
    async with pf_offboard.connect(endpoint) as vehicle:
        await vehicle.takeoff(2.0)
        loop = await vehicle.follow(LOOP, speed=1.5, laps=1)
        print("loop:", loop.reason, f"{loop.whole_cross_track_rms_m:.3f} m (convergence included)")
        line = await vehicle.follow(LINE, speed=1.0)  # open: ends at the last way-point
        print("line:", line.reason, f"{line.whole_cross_track_rms_m:.3f} m (convergence included)")
        await vehicle.hand_back()


asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udp://:14540"))
