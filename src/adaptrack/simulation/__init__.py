"""Simulation of truth trajectories and measurements."""

from .linear import simulate_linear_measurements, simulate_linear_trajectory

__all__ = ["simulate_linear_measurements", "simulate_linear_trajectory"]
