"""Robot model of the mecanum robot."""
