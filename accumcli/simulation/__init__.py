"""Synthetic stereo recordings with ground truth (``accum simulate``)."""

from .random_scene import BACKGROUNDS, RANDOM_SHAPES
from .scene import SHAPES
from .simulate import (
           SCENES,
           SimulationOptionError,
           SimulationOptions,
           SimulationResult,
           simulate,
)

__all__ = ["BACKGROUNDS", "RANDOM_SHAPES", "SCENES", "SHAPES", "SimulationOptionError", "SimulationOptions",
           "SimulationResult", "simulate"]
