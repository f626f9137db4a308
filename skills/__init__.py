"""Backend-agnostic skills. They only talk to the device interfaces in ``drivers``."""
