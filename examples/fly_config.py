"""Take off, follow a config's path for one lap, hand back (hold).

    python fly_config.py [ENDPOINT] [CONFIG]      # default: udp://:14540 px4-sih
"""
import asyncio
import sys

import pf_offboard


async def main(endpoint: str, config: str) -> None:
    async with pf_offboard.connect(endpoint) as vehicle:  # waits for the autopilot's HEARTBEAT
        await vehicle.takeoff(2.0)  # returns once the altitude is held
        result = await vehicle.follow(config, laps=1)  # a config file or a shipped config's name
        print(result.reason, f"cross-track RMS {result.cross_track_rms_m:.3f} m", f"speed error RMS {result.speed_error_rms_m_s:.3f} m/s")
        await vehicle.hand_back()  # hold, confirmed by the autopilot


asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udp://:14540", sys.argv[2] if len(sys.argv) > 2 else "px4-sih"))
