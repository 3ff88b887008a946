"""Localization of the mecanum robot."""
