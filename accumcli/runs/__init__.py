"""Library runs: each does one whole job of the command line and returns a result object."""

from .accumulation import AccumulationResult, accumulate_recording
from .base import FrameRange, Progress, RecordingOptions
from .evaluation import evaluate_file
from .extraction import ExtractionResult, extract_recording
from .information import describe_recording
from .still import check_model
from .tracking import TrackingResult, track_recording
from .viewing import view

__all__ = ["AccumulationResult", "ExtractionResult", "FrameRange", "Progress", "RecordingOptions",
           "TrackingResult", "accumulate_recording", "check_model", "describe_recording", "evaluate_file",
           "extract_recording", "track_recording", "view"]
