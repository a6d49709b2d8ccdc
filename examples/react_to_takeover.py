"""Follow a closed path until the pilot takes over, and say what happened.

The app yields at once when the mode changes to one it did not ask for (RC switch, ground
station): it stops sending and never re-engages; the exception carries the partial result.

    python react_to_takeover.py [ENDPOINT] [CONFIG]
"""
import asyncio
import sys

import pf_offboard


async def main(endpoint: str, config: str) -> None:
    async with pf_offboard.connect(endpoint) as vehicle:
        await vehicle.takeoff(2.0)
        try:
            await vehicle.follow(config)  # a closed path: until stopped
        except pf_offboard.OperatorTakeover as takeover:
            print(f"the pilot took over after {takeover.result.laps:.2f} laps: {takeover}")
        except pf_offboard.FlightError as other:  # breach, crash, lost link, refused command, failsafe
            print(f"ended with exit code {other.exit_code}: {other}")


asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udp://:14540", sys.argv[2] if len(sys.argv) > 2 else "px4-sih"))
