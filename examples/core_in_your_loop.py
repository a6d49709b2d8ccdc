"""The path-following core in your own simulator loop: a point-mass vehicle flies a closed path."""
import numpy as np

from pf_offboard import Path, PathFollower

path = Path.from_waypoints([[0, -1.5, 2], [1.5, 0, 2.5], [0, 1.5, 2], [-1.5, 0, 1.5]], closed=True)
follower = PathFollower(path, speed=1.5)  # m/s along the path; its sign picks the direction
p, v, dt = np.array([0.0, -2.5, 1.0]), np.zeros(3), 0.01  # ENU position (m), velocity (m/s), step (s)
for _ in range(3000):  # 30 s; your simulator goes here
    cmd = follower.update(p, v)  # acceleration demand, ENU, gravity excluded
    v = v + cmd.acceleration * dt
    p = p + v * dt
print(f"after 30 s: {cmd.cross_track_m:.4f} m from the path at {np.linalg.norm(v):.2f} m/s")
