"""The local controller (holonomic trajectory sampling) and the velocity smoother."""
