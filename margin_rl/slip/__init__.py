"""Actuated SLIP hopper, its learned failure-margin function and footstep planner (seed 001)."""
