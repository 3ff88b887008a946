"""Costmaps: static, keepout, obstacle and inflation layers, and their compiled kernels."""
