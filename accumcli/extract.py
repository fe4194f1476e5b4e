"""One stereo frame in, local 3D line segments (left camera frame) out:
2D local segments in both images (``lines2d``), stereo matching (``stereo``), a
search of the right image for the left segments matching left alone (``guided``)
and triangulation (``stereo``), with a per-stage time breakdown. The frame's image
gradients are returned too, for tracking in the same frame to reuse."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from .lines2d import DETECTORS, Gradients, LineParams, Segments2D, StageTimes
from .recording import StereoFrame
from .critical import triangulate_critical
from .guided import GuidedParams, guided_matches
from .segments import Segments, concatenate
from .stereo import Matches, StereoParams, crowding, match, triangulate


@dataclass(frozen=True)
class ExtractParams:
    lines: LineParams = field(default_factory=LineParams)
    stereo: StereoParams = field(default_factory=StereoParams)
    guided: GuidedParams = field(default_factory=GuidedParams)


@dataclass
class FrameSegments:
    """What one frame gave: 3D segments (camera frame, in ``segments.frame_id``), the
    2D segments of both images, which left/right 2D segments each 3D one came
    from (right -1 for a critical one, triangulated from its run's ends), counts (2D segments,
    critical, critical triangulated, unmatched, 3D), and the (left, right)
    image gradients it used (``refine_pose`` and ``PoseTracker.update`` take them)."""

    index: int
    timestamp_ns: int
    segments: Segments
    left: Segments2D
    right: Segments2D
    left_index: np.ndarray
    right_index: np.ndarray
    counts: dict
    gradients: tuple[Gradients, Gradients] | None = None


def extract_frame(frame: StereoFrame, params: ExtractParams = ExtractParams(), camera_frame: str = "camera_left",
                  times: StageTimes | None = None,
                  gradients: tuple[Gradients, Gradients] | None = None) -> FrameSegments:
    """Local 3D line segments of one rectified stereo frame. ``gradients``: the frame's (left,
    right) ``Gradients`` if already computed (e.g. ``lines2d.frame_gradients(frame,
    params.lines)``, also given to tracking), reused as ``Gradients.of(..., reuse=)`` says;
    the gradients used are returned in the result."""
    times = times or StageTimes()
    detect = DETECTORS[params.lines.detector]
    sides, grads = [], []
    border = frame.border_distance or (None, None)
    for side, image in enumerate((frame.left, frame.right)):
        t0 = time.perf_counter()
        grad = Gradients.of(image, params.lines, gradients[side] if gradients is not None else None,
                            border[side])
        times.add("gradients", t0)
        sides.append(detect(image, params.lines, grad, times))
        grads.append(grad)
    left, right = sides
    t0 = time.perf_counter()
    m: Matches = match(frame.left, frame.right, left, right, frame.intrinsics, params.stereo)
    detected_right = len(right)
    m, right = guided_matches(frame.left, frame.right, left, right, m, grads[1], frame.intrinsics, params.stereo,
                              params.guided)
    t0 = times.add("matching", t0)
    # once: triangulation and the critical pieces take it; beyond crowded_far_px it widens no sigma
    crowd = crowding(left, params.stereo.crowded_far_px), crowding(right, params.stereo.crowded_far_px)
    segments, kept = triangulate(left, right, m, frame.intrinsics, params.stereo, camera_frame, crowd)
    t0 = times.add("triangulation", t0)
    by_ends, critical_left = triangulate_critical(frame.left, frame.right, left, tuple(grads), frame.intrinsics,
                                                  params.stereo, camera_frame, segments, left.select(m.left[kept]),
                                                  left_crowding=crowd[0])
    times.add("critical", t0)
    # right_2d: what the detector found; right_found: what the right-image search added (``guided``)
    counts = {"left_2d": len(left), "right_2d": detected_right, "right_found": len(right) - detected_right,
              "critical": m.critical, "critical_3d": len(by_ends), "unmatched": m.unmatched + (len(m.left) - len(kept)),
              "segments": len(segments) + len(by_ends)}
    # a critical segment's 3D comes from its run's ends, not from one right segment: right index -1
    return FrameSegments(frame.index, frame.timestamp_ns, concatenate([segments, by_ends], camera_frame), left,
                         right, np.concatenate([m.left[kept], critical_left]),
                         np.concatenate([m.right[kept], np.full(len(critical_left), -1)]), counts, tuple(grads))
