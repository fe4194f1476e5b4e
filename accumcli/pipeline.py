"""Accumulating a line model over a recording's frames: extraction, the known
motion, and the accumulation core, one frame at a time."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .accumulate import Accumulator, StepStats, UpdateRule
from .errors import InputError
from .extract import ExtractParams, FrameSegments, extract_frame
from .geometry import inside_box, invert, mean_transform, pose_error, rotate_vectors, transform_points
from .line_model import (FrameContext, LineModelParams, LineSegmentType, direction_known, merged_twins,
                         planes_from_image, shared_directions, to_model)
from .lines2d import Gradients, Segments2D, StageTimes
from .recording import StereoFrame
from .segments import Segments, concatenate
from .temporal_lines import TemporalLines, TemporalParams
from .track import PoseEstimate, TrackParams, refine_pose

log = logging.getLogger("accumcli")


MOTIONS = ("gripper", "tracked")


def check_box(box, form: str = "box ((x_min, x_max), (y_min, y_max), (z_min, z_max)) in metres, object frame",
              shown=None) -> tuple | None:
    """``box`` (None, or three (min, max) pairs, metres, object frame) as a tuple of float pairs;
    ``InputError`` unless each is finite with its minimum below its maximum and the box is at most 10 m
    across (around an object a gripper holds: more is millimetres, most likely). The message names the
    ``form`` expected and ``shown`` (default: ``box``) as what was found."""
    if box is None:
        return None
    shown = box if shown is None else shown
    try:
        pairs = tuple(tuple(float(v) for v in pair) for pair in box)
    except (TypeError, ValueError):
        raise InputError(f"expected {form}, found {shown!r}") from None
    if len(pairs) != 3 or any(len(pair) != 2 for pair in pairs):
        raise InputError(f"expected {form}, found {shown!r}")
    if not all(np.isfinite(lo) and np.isfinite(hi) and lo < hi for lo, hi in pairs):
        raise InputError(f"expected {form} with each minimum below its maximum, found {shown!r}")
    across = max(hi - lo for lo, hi in pairs)
    if across > 10.0:
        raise InputError(f"expected {form}: a box {across:g} m across, found {shown!r} (millimetres? give metres)")
    return pairs


@dataclass(frozen=True)
class AccumulateParams:
    """``motion``: 'gripper' uses the recorded pose of every frame (the paper); 'tracked' uses the
    poses repaired in passes over the recording (``motion``, ``runs.accumulation.tracked_poses``) when
    the caller gives them to ``LineAccumulation.step``, and otherwise (one frame at a time) refines
    the recorded pose on the images against the current model (``track.refine_pose``; against all its
    segments until ``min_tracking_segments`` are accepted), using it where tracking succeeds and it
    moves the recorded one by less than ``max_correction_deg`` / ``max_correction_m``; that one-pass
    refinement fails at 1.5 deg / 4 mm of noise (the young model holds background, the later one is
    smeared).

    ``box`` ((3, 2) metres, object frame, per axis min and max; None: everywhere): a frame's 3D
    segments whose centre lies outside are dropped before the update, so they neither create nor
    confirm a model segment. For what moves with the object but is not the object (a fixture, a board
    it stands on, the gripper's fingers), which the motion cannot tell from it. The real teabox stands
    on a board turned with it: a box 10 mm around the tea box took its model's (frames 0:40)
    precision on the box's surface from 0.57 to 0.72, completeness 0.454 both; what is left off the
    surface lies within the box, a few mm off the faces (the peer poses' depth offset).

    ``temporal`` (None: stereo alone, the paper's and the default): the frame's 3D segments also take
    lines triangulated across frames with the used motion (``temporal_lines``: a left piece's plane
    meets a piece's plane of a frame 2 or 4 back, and four of the five other buffered views show a
    piece along the line): of the pieces stereo left (unmatched, critical), and ('replace') in place of
    a stereo segment whose direction they know better, within four of its depth sigmas of it. They
    trust the relative poses to a tenth of a degree (not for poses a degree off). Measured on ``make
    suite`` in ``temporal_lines``' docstring, and why it is off by default."""

    extract: ExtractParams = field(default_factory=ExtractParams)
    line_model: LineModelParams = field(default_factory=LineModelParams)
    rule: UpdateRule = field(default_factory=UpdateRule)
    motion: str = "gripper"
    track: TrackParams = field(default_factory=TrackParams)
    min_tracking_segments: int = 30
    max_correction_deg: float = 10.0
    max_correction_m: float = 0.03
    box: tuple | None = None          # ((x_min, x_max), (y_min, y_max), (z_min, z_max))
    temporal: TemporalParams | None = None   # lines triangulated across frames too (below; None: stereo alone)
    temporal_mode: str = "replace"    # 'unused': of pieces stereo left; 'replace': and where surer than stereo

    def __post_init__(self):
        if self.motion not in MOTIONS:
            raise InputError(f"motion {self.motion!r}: expected one of {', '.join(MOTIONS)}")
        if self.motion == "tracked" and self.temporal is not None:
            # the repaired poses are half a degree off: the lines trust the relative poses to a tenth of one
            raise InputError("--across-frames needs the recorded poses: with --motion tracked they are half a degree "
                             "off; drop one of the two")
        if self.temporal_mode not in ("unused", "replace"):
            raise InputError(f"temporal_mode {self.temporal_mode!r}: expected 'unused' or 'replace'")
        if self.motion == "tracked" and self.rule.image_confirmation is not None:
            # a pose refined on the images puts the model on their edges: they would confirm themselves
            raise InputError("--image-confirm needs the recorded poses: with --motion tracked the poses are fitted "
                             "to the same images; drop one of the two")
        object.__setattr__(self, "box", check_box(self.box))
        # A segment is expected in a frame only where it could have been extracted there, so the line
        # model's critical angle is always the extraction's (one setting, however the params are built).
        critical = self.extract.stereo.critical_angle_deg
        if self.line_model.critical_angle_deg != critical:
            object.__setattr__(self, "line_model", replace(self.line_model, critical_angle_deg=critical))


@dataclass
class AccumulationStep:
    """One frame's contribution: its extraction, the pose used (and, with tracked motion, the
    refinement's estimate), and the update's counts."""

    frame: StereoFrame
    extraction: FrameSegments
    T_camera_object: np.ndarray
    stats: StepStats
    tracking: PoseEstimate | None = None
    outside_box: int = 0     # 3D segments dropped outside ``AccumulateParams.box``
    across_frames: int = 0   # of the 3D segments, lines triangulated across frames (``AccumulateParams.temporal``)
    replaced: int = 0        # ... of them in place of a stereo segment


class LineAccumulation:
    """The model of one object, grown frame by frame (object frame ``frame_id``).

    With tracked motion the model is built in the frame of the first recorded
    pose, which carries that pose's error; every refined frame measures
    ``T_recorded_model = T_recorded^-1 T_refined``, the model's frame in the
    recorded object frame. The recorded poses are unbiased, so the mean of
    these is the first pose's error, and ``model()`` returns the model moved by
    it into the object frame (the gauge is fixed by all frames, not one).
    """

    def __init__(self, params: AccumulateParams = AccumulateParams(), frame_id: str = "gripper",
                 camera_frame: str = "camera_left"):
        self.params = params
        self.camera_frame = camera_frame
        self.entity_type = LineSegmentType(params.line_model)
        self.core = Accumulator(self.entity_type, self.entity_type.empty(frame_id), params.rule)
        self.times = StageTimes()
        self.T_recorded_model: list[np.ndarray] = []   # T_recorded^-1 T_refined of the refined frames
        self._shared: Segments | None = None    # the directions the model shares, as of the last frame
        self._temporal = None if params.temporal is None else TemporalLines(params.temporal, camera_frame)

    def extract(self, frame: StereoFrame) -> FrameSegments:
        return extract_frame(frame, self.params.extract, self.camera_frame, self.times)

    def step(self, frame: StereoFrame, T_camera_object: np.ndarray,
             extraction: FrameSegments | None = None, T_corrected: np.ndarray | None = None,
             pose_covariance: np.ndarray | None = None) -> AccumulationStep:
        """Extract (unless given) and accumulate one frame seen at pose ``T_camera_object`` (recorded).
        With tracked motion, ``T_corrected`` (4, 4; ``runs.accumulation.tracked_poses``, the passes of
        ``motion``) is used instead of the refinement against the model so far, which is the
        one-pass fallback (it fails at 1.5 deg / 4 mm of noise: see ``motion``). ``pose_covariance``
        (6, 6; ``motion.fuse``): the used pose's uncertainty, which the observations take on
        (``FrameContext``); None: the pose is taken as exact."""
        extraction = extraction or self.extract(frame)
        estimate = None
        if self.params.motion == "tracked" and T_corrected is not None:
            self.T_recorded_model.append(invert(T_camera_object) @ T_corrected)
            T_camera_object = T_corrected
        elif self.params.motion == "tracked":
            T_camera_object, estimate = self._refined(frame, T_camera_object, extraction)
        context = FrameContext(T_camera_object, frame.intrinsics, frame.border_distance,
                               *self._miss_test_inputs(frame, extraction), shared=self._shared,
                               pose_covariance=pose_covariance, right_gradients=self._right_gradients(frame, extraction))
        segments = extraction.segments
        # the lines across frames among the segments, the pieces they came from, the stereo segments replaced
        across, lined, replaced = np.zeros(len(segments), bool), np.zeros(0, np.int64), 0
        if self._temporal is not None:
            t0 = time.perf_counter()
            segments, across, lined, replaced = self._with_temporal(frame, extraction, T_camera_object)
            self.times.add("across frames", t0)
        given = len(segments)
        if self.params.box is not None:
            inside = inside_box(transform_points(invert(T_camera_object), segments.centers),
                                np.asarray(self.params.box, float))
            segments, across = segments.select(inside), across[inside]
        stats = self.core.update(segments, invert(T_camera_object), context)
        core, rules = self.core, self.params.line_model
        known = direction_known(core.entities, rules)
        if rules.view_planes and rules.image_planes and len(core):
            # the core's frame counter has moved on: this frame's confirmations say frame - 1
            unsure = (core.log_odds >= 0) & (core.last_confirmed != core.frame - 1) & ~known
            unused = np.ones(len(extraction.left), bool)
            unused[extraction.left_index] = False
            unused[lined] = False        # a piece that gave a line across frames gives no plane again
            taken = planes_from_image(core.entities, unsure, extraction.left.select(unused), context, rules)
            known[taken] = direction_known(core.entities.select(taken), rules)
        # accepted as the model is written (``to_model``: a segment's direction must be sure too)
        stats.accepted = int(np.sum((core.log_odds >= 0) & known))
        if rules.dominant is not None and rules.dominant.observations:     # for the next frame's observations
            self._shared = shared_directions(core.entities, (core.log_odds >= 0) & known, rules)
        log.debug("frame %d: %s", frame.index, ", ".join(f"{k} {v}" for k, v in stats.__dict__.items()))
        return AccumulationStep(frame, extraction, T_camera_object, stats, estimate, given - len(segments),
                                int(across.sum()), replaced)

    def _with_temporal(self, frame: StereoFrame, extraction: FrameSegments, T_camera_object: np.ndarray
                       ) -> tuple[Segments, np.ndarray, np.ndarray, int]:
        """The frame's stereo segments with those triangulated across frames (``temporal_lines``): of the
        pieces stereo left ('unused'), and ('replace') in place of a stereo segment whose direction they
        know better; which of the segments are such lines (bool), the left pieces they came from, and
        how many stereo segments they replaced."""
        stereo = extraction.segments
        segment_of_piece = np.full(len(extraction.left), -1)
        segment_of_piece[extraction.left_index] = np.arange(len(extraction.left_index))
        wanted = segment_of_piece < 0
        if self.params.temporal_mode == "replace" and len(stereo):   # and where stereo is less sure than they can be
            floor = np.radians(self.params.temporal.direction_floor_deg)
            wanted |= stereo.extra["sigma_direction_rad"][np.maximum(segment_of_piece, 0)] > floor
        # a piece that stereo placed: its line across frames within 4 sigmas (and 3 mm) of that distance
        distance = np.full((2, len(extraction.left)), np.nan)
        if len(stereo):
            placed = segment_of_piece >= 0
            k = segment_of_piece[placed]
            middle = np.linalg.norm(stereo.centers[k], axis=1)
            slack = 4 * stereo.extra["sigma_depth_m"][k] * middle / np.maximum(stereo.centers[k, 2], 1e-9) + 0.003
            distance[:, placed] = middle - slack, middle + slack
        found = self._temporal.step(extraction.left, T_camera_object, frame.intrinsics, frame.index, wanted, distance)
        if not len(found):
            return stereo, np.zeros(len(stereo), bool), np.zeros(0, np.int64), 0
        found.frame_id = stereo.frame_id
        k = segment_of_piece[found.extra["piece"]]
        used = k >= 0
        keep_stereo = np.ones(len(stereo), bool)
        if self.params.temporal_mode == "replace" and used.any():
            surer = used & (found.extra["sigma_direction_rad"] < stereo.extra["sigma_direction_rad"][np.maximum(k, 0)])
            keep_stereo[k[surer]] = False
            take = ~used | surer
        else:
            take = ~used
        kept = int(keep_stereo.sum())
        return (concatenate([stereo.select(keep_stereo), found.select(take)], stereo.frame_id),
                np.arange(kept + int(take.sum())) >= kept, found.extra["piece"][take], len(stereo) - kept)

    def _miss_test_inputs(self, frame: StereoFrame, extraction: FrameSegments
                          ) -> tuple[Gradients | None, Segments2D | None]:
        """The left image's gradients and the left pieces that became 3D segments, for ``expected``'s
        test of what the extraction missed and ``image_confirmed`` ((None, None) when both are off): the
        extraction's gradients, or computed again where a helper process or a replay dropped them
        (``runs.parallel``, ``runs.accumulation.ExtractionStore``)."""
        if not (self.params.line_model.unextracted_no_miss or self.params.rule.image_confirmation is not None):
            return None, None
        return self._gradients(frame, extraction, 0), extraction.left.select(extraction.left_index)

    def _right_gradients(self, frame: StereoFrame, extraction: FrameSegments) -> Gradients | None:
        """The right image's gradients for ``image_confirmed`` (None where ``image_confirmation`` is off)."""
        return None if self.params.rule.image_confirmation is None else self._gradients(frame, extraction, 1)

    def _gradients(self, frame: StereoFrame, extraction: FrameSegments, side: int) -> Gradients:
        """The extraction's gradients of the left (``side`` 0) or right (1) image, or computed again where a
        helper process or a replay dropped them."""
        if extraction.gradients is not None:
            return extraction.gradients[side]
        border = frame.border_distance
        return Gradients.of((frame.left, frame.right)[side], self.params.extract.lines,
                            border_distance=border[side] if border is not None else None)

    def _written(self, uncertainty: bool = True) -> Segments:
        """The core's segments as ``to_model`` writes them, with this run's acceptance rules (its twins
        merged first, ``merged_twins``, unless ``LineModelParams.merge_twins`` is off)."""
        rules = self.params.line_model
        core = merged_twins(self.core, rules) if rules.merge_twins else self.core
        return to_model(core.entities, core.confidence, core.observations, uncertainty=uncertainty, rules=rules)

    def _refined(self, frame: StereoFrame, T_recorded: np.ndarray,
                 extraction: FrameSegments) -> tuple[np.ndarray, PoseEstimate | None]:
        p = self.params
        track = p.track
        model = self._written(uncertainty=False)
        if model.accepted.sum() < p.min_tracking_segments:
            # bootstrap: until enough segments are accepted, refine against the tentative ones too
            # (the background among them does not follow the object and falls to the robust weights;
            # it lowers the coverage, so that check waits for the accepted model, the others stay)
            model.confidence = np.maximum(model.confidence, 0.5)
            track = replace(track, min_coverage=0.0)
            if len(model) < p.min_tracking_segments:
                return T_recorded, None
        t0 = time.perf_counter()
        estimate = refine_pose(model, frame, T_recorded, track, gradients=extraction.gradients)
        self.times.add("tracking", t0)
        rotation, translation = pose_error(estimate.T_camera_object, T_recorded)
        # only a verified pose moves the recorded one: never an 'ambiguous' or 'lost' refinement
        if estimate.status != "tracked" or rotation > p.max_correction_deg or translation > p.max_correction_m:
            return T_recorded, estimate
        self.T_recorded_model.append(invert(T_recorded) @ estimate.T_camera_object)
        return estimate.T_camera_object, estimate

    def T_object_model(self) -> np.ndarray:
        """(4, 4) the model's frame in the object frame: the mean offset of the refined frames (with
        tracked motion; the identity without; see the class docstring). A pose T_camera_model used to
        accumulate is ``T_camera_model @ invert(T_object_model())`` in the object frame of ``model()``."""
        return mean_transform(np.stack(self.T_recorded_model)) if self.T_recorded_model else np.eye(4)

    def model(self) -> Segments:
        """The current model: every live segment with its confidence and observation count (with
        tracked motion, moved into the object frame by the mean offset; see the class docstring)."""
        model = self._written()
        if not self.T_recorded_model:
            return model
        T_object_model = self.T_object_model()
        moved = model.transformed(T_object_model, model.frame_id)
        moved.extra = {**model.extra, "view_direction": rotate_vectors(T_object_model, model.extra["view_direction"])}
        return moved
