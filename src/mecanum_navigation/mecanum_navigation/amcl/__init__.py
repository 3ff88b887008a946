"""Localisation on a saved map: adaptive Monte Carlo localisation (nav2_amcl's job)."""
