"""Bringup of the mecanum robot."""
