"""Benchmark: the twin's wrist-camera render time at a low, tilted grasp pose.

Run by hand:  python bench/camera_render.py [--width 424 --height 240] [--repeats 3]

At the emulated cell's Grasp (joint angles read from one) the finger boxes' bases lie in the
eye-in-hand camera's plane. TinyRenderer does not clip at the near plane; drawn, such a face
took about 10 s to rasterise, which stalled the emulated D435 (it renders continuously) for
whole Looks. :class:`sim.camera.SimCamera` leaves links that cross the near plane out of the
frame. This prints the render time with that (as shipped) and without it, and at the home
pose for scale. Numbers are for this machine only.
"""

from __future__ import annotations

import argparse
import statistics
import time

from sim.camera import SimCamera, d435_intrinsics
from sim.robot import SimRobot
from sim.world import SimWorld

GRASP = (2.9348, -1.3795, 1.9178, -1.8303, -1.6298, 1.3677)  #: rad, joints 1-6
FINGER_Q = 0.04  #: m, each finger joint at that pose


def _time(cam: SimCamera, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        cam.render(cam.world_T_camera())
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=424)
    ap.add_argument("--height", type=int, default=240)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    with SimWorld(seed=0) as world:
        robot = SimRobot(world)
        p = world.p
        col = p.createCollisionShape(p.GEOM_BOX, halfExtents=[0.4, 0.4, 0.025])
        vis = p.createVisualShape(p.GEOM_BOX, halfExtents=[0.4, 0.4, 0.025])
        p.createMultiBody(0.0, col, vis, basePosition=[0.45, 0.0, -0.025])
        cam = SimCamera(world, lambda: robot.world_pose(robot.arm.tool_pose()),
                        intrinsics=d435_intrinsics(args.width, args.height), noise=None)
        home = _time(cam, args.repeats)
        for j, q in zip(range(1, 7), GRASP, strict=True):
            p.resetJointState(robot.body_id, j, q)
        names = {p.getJointInfo(robot.body_id, j)[12].decode(): j
                 for j in range(p.getNumJoints(robot.body_id))}
        for name in ("finger_a", "finger_b"):
            p.resetJointState(robot.body_id, names[name], FINGER_Q)
        shipped = _time(cam, args.repeats)
        cam._hide_links_crossing_near = lambda pose: []  # type: ignore[method-assign]
        drawn = _time(cam, args.repeats)
    print(f"render {args.width}x{args.height}, median of {args.repeats}:")
    print(f"  home pose                               {home * 1000:8.1f} ms")
    print(f"  grasp pose, near-plane links left out   {shipped * 1000:8.1f} ms")
    print(f"  grasp pose, every link drawn            {drawn * 1000:8.1f} ms")


if __name__ == "__main__":
    main()
