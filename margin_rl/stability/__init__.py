"""Stability layer: analytic feasible region and margin, learned margin (robot-agnostic core)."""
