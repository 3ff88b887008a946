"""Motor control of the mecanum robot."""
