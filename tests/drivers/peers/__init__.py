"""Protocol peers of the real devices, for the driver tests."""
