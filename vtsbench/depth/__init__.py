"""Depth: sphere calibration, gradient mapping, Poisson integration and depth metrics."""
