"""Synthetic stereo recordings with ground truth (``accum simulate``)."""

from .scene import SHAPES
from .simulate import SimulationOptions, SimulationResult, simulate

__all__ = ["SHAPES", "SimulationOptions", "SimulationResult", "simulate"]
