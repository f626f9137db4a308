"""The PyBullet twin: implements the device interfaces of ``drivers``."""
