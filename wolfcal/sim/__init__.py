"""Synthetic robots, scenes and captures with known ground truth."""
