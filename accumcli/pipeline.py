"""Accumulating a line model over a recording's frames: extraction, the known
motion, and the accumulation core, one frame at a time."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .accumulate import Accumulator, StepStats, UpdateRule
from .extract import ExtractParams, FrameSegments, extract_frame
from .geometry import invert
from .line_model import FrameContext, LineModelParams, LineSegmentType, to_model
from .lines2d import StageTimes
from .recording import StereoFrame
from .segments import Segments


@dataclass(frozen=True)
class AccumulateParams:
    extract: ExtractParams = field(default_factory=ExtractParams)
    line_model: LineModelParams = field(default_factory=LineModelParams)
    rule: UpdateRule = field(default_factory=UpdateRule)


@dataclass
class AccumulationStep:
    """One frame's contribution: its extraction, the pose used, and the update's counts."""

    frame: StereoFrame
    extraction: FrameSegments
    T_camera_object: np.ndarray
    stats: StepStats


class LineAccumulation:
    """The model of one object, grown frame by frame (object frame ``frame_id``)."""

    def __init__(self, params: AccumulateParams = AccumulateParams(), frame_id: str = "gripper",
                 camera_frame: str = "camera_left"):
        self.params = params
        self.camera_frame = camera_frame
        self.entity_type = LineSegmentType(params.line_model)
        self.core = Accumulator(self.entity_type, self.entity_type.empty(frame_id), params.rule)
        self.times = StageTimes()

    def extract(self, frame: StereoFrame) -> FrameSegments:
        return extract_frame(frame, self.params.extract, self.camera_frame, self.times)

    def step(self, frame: StereoFrame, T_camera_object: np.ndarray,
             extraction: FrameSegments | None = None) -> AccumulationStep:
        """Extract (unless given) and accumulate one frame seen at pose ``T_camera_object``."""
        extraction = extraction or self.extract(frame)
        context = FrameContext(T_camera_object, frame.intrinsics)
        stats = self.core.update(extraction.segments, invert(T_camera_object), context)
        return AccumulationStep(frame, extraction, T_camera_object, stats)

    def model(self) -> Segments:
        """The current model: every live segment with its confidence and observation count."""
        return to_model(self.core.entities, self.core.confidence, self.core.observations)
