"""Navigation of the mecanum robot."""
