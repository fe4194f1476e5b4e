"""Recording I/O: the only part of accum that knows MCAP (reading, writing,
transform tree, calibration and rectification)."""

from .calibration import CameraCalibration, StereoIntrinsics, StereoRectifier
from .reader import Recording, RecordingInfo, StereoFrame, Topics
from .tf_tree import TransformSamples, TransformTree
from .writer import RecordingWriter, Rosbag2Writer

__all__ = ["CameraCalibration", "Recording", "RecordingInfo", "RecordingWriter", "Rosbag2Writer", "StereoFrame",
           "StereoIntrinsics", "StereoRectifier", "Topics", "TransformSamples", "TransformTree"]
