"""Simulated mecanum robot and world for safe, isolated testing."""
