"""Text commands to velocity commands for the mecanum robot."""
