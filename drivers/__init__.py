"""Device interfaces (arm, gripper, force-torque sensor, camera) and the real drivers."""
