"""``evaluate_file``: a model, frames file or poses file measured against a truth sidecar."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..evaluate import Tolerances, evaluate_frames, evaluate_model, pose_errors
from ..funnel import funnel
from ..model_io import (check_kind, load_model_doc, pose_of_fields, read_frames, read_poses, read_truth,
                        segments_from_dict)
from ..outputs import OutputSet
from ..surface import faces_of, frame_surface_scores, hidden_face, support_face_problem, surface_scores
from .base import FrameRange, frame_range
from .checks import check_same_time, check_truth_matches, check_truth_poses, check_truth_times

TIME_TOLERANCE_NS = 1_000_000
log = logging.getLogger("accumcli")


def evaluate_file(path, truth_path, tol: Tolerances = Tolerances(), frames: FrameRange = FrameRange(),
                  support_face: int | None = None, plot=None) -> dict:
    """Figures of ``path`` against the truth, by the kind of ``path`` (recognised by content): a model
    (precision, completeness, background of the accepted segments), a frames file (single-frame
    figures and the funnel, ``accumcli.funnel``) or a poses file (pose errors, tracked fraction).
    ``frames`` selects lines of a frames or poses file by position. A truth of another object frame,
    or one with no pose at the file's timestamps, is refused. A truth with ``faces`` also gives a
    model's precision judged by surface, and a frames file's segments per frame on the body
    (``accumcli.surface``; ``support_face``: the face it stands on).
    ``plot``: a PNG of a frames file's figures frame by frame (``plots``)."""
    frames = frame_range(frames)
    if not isinstance(path, (str, os.PathLike)) or not isinstance(truth_path, (str, os.PathLike)):
        raise InputError("evaluate_file: expected the paths of a model, frames or poses file and of a truth")
    truth = read_truth(truth_path)
    kind = check_kind(path, "model", "frames", "poses")
    if plot and kind != "frames":
        raise InputError(f"{path}: --plot draws a frames file's figures frame by frame; this is a {kind} file")
    if kind == "model" and frames != FrameRange():
        raise InputError(f"{path}: --frames selects lines of a frames or poses file; a model has none")
    if kind == "model":
        doc = load_model_doc(path)
        model = segments_from_dict(doc, str(path))
        check_truth_matches(truth, model.frame_id, truth_path)
        span = doc.get("source_times_ns")   # written by accum accumulate (not by the contract: may be absent)
        if isinstance(span, list) and len(span) == 2 and all(isinstance(t, int) for t in span):
            check_same_time(truth.times_ns, span, TIME_TOLERANCE_NS, truth_path,
                            f"the frames {path} was accumulated over")
        figures = evaluate_model(model, truth, tol)
        if figures.get("accepted") and figures.get("precision") == 0:
            log.warning("%s: none of its %d accepted segments lies on an edge of %s: is it the truth of this "
                        "recording?", path, figures["accepted"], truth_path)
        faces = _faces(truth, truth_path, support_face)
        if faces:
            figures.update(surface_scores(model, faces, tol, support_face))
        return figures
    if kind == "poses":
        track = read_poses(path)
        check_truth_matches(truth, track.child_frame_id, truth_path, "the poses")
        keep = slice(frames.start, frames.stop)
        times = track.times_ns[keep]
        _check_selected(len(times), len(track.times_ns), frames, path)
        check_truth_times(truth, times, TIME_TOLERANCE_NS, path, truth_path)
        return _warn_unjudged(pose_errors(times, track.poses[keep], track.status[keep], truth), path, truth_path)
    if kind == "frames":
        rows = [row for i, row in enumerate(read_frames(path))
                if frames.contains(i)]
        times = np.array([t for t, _, _ in rows], np.int64)
        if not rows:
            _check_selected(0, sum(1 for _ in read_frames(path)), frames, path)
        check_truth_times(truth, times, TIME_TOLERANCE_NS, path, truth_path)
        recorded = [(t, row["T_camera_object"]) for t, _, row in rows if isinstance(row.get("T_camera_object"), dict)]
        check_truth_poses(truth, [t for t, _ in recorded], [_recorded_pose(p) for _, p in recorded], path, truth_path,
                          TIME_TOLERANCE_NS)
        per_frame, segments = [], [(t, s) for t, s, _ in rows]
        figures = {**evaluate_frames(segments, truth, tol, per_frame),
                   **funnel(rows, truth, tol)}
        index_of = {t: row["frame_index"] for t, _, row in rows if isinstance(row.get("frame_index"), int)}
        for r in per_frame:   # the recording's frame numbers where the file has them, not the lines'
            r["frame_index"] = index_of.get(r["timestamp_ns"], r["frame_index"])
        faces = _faces(truth, truth_path, support_face)
        if faces:
            figures.update(frame_surface_scores(segments, truth, faces, tol, support_face))
        _warn_unjudged(figures, path, truth_path)
        if plot:
            from ..plots import plot_frames

            with OutputSet([plot], inputs=[path, truth_path]) as files:
                plot_frames(files.open(plot, "wb"), per_frame, f"accum eval {Path(path).name}: single frames")
        return figures
    raise InputError(f"{path}: expected a model, frames or poses file of accum to evaluate, got a {kind} file")


def _faces(truth, truth_path, support_face: int | None) -> list:
    """The truth's faces for figures by surface (``accumcli.surface``), ``support_face`` checked
    (``InputError`` if the truth has no such face, or no faces at all; a warning if the truth's poses
    show that face to the cameras, or if no support face is given where one face is hidden in every
    frame)."""
    faces = faces_of(truth.meta)
    if not faces:
        if support_face is not None:
            raise InputError(f"{truth_path}: the truth has no faces, so no support face {support_face}")
        return faces
    if support_face is not None and not 0 <= support_face < len(faces):
        raise InputError(f"{truth_path}: no face {support_face} (the truth has {len(faces)} faces)")
    problem = None if support_face is None else support_face_problem(faces, support_face, truth.poses)
    if problem:
        log.warning("%s: %s", truth_path, problem)
    hidden = hidden_face(faces, truth.poses) if support_face is None else None
    if hidden is not None:
        log.warning("%s: surface figures count the object's faces only; if it stands on a board that "
                    "moves with it, give --support-face %d (the face turned away from the cameras "
                    "the most) to count the board's plane too", truth_path, hidden)
    return faces


def _recorded_pose(doc: dict) -> np.ndarray | None:
    """A frames file line's recorded ``T_camera_object`` (4, 4), None where malformed."""
    try:
        return pose_of_fields(doc)
    except (KeyError, TypeError, ValueError):
        return None


def _warn_unjudged(figures: dict, path, truth_path) -> dict:
    """Say so when some frames of ``path`` have no truth pose: the figures judge only the others."""
    missing = figures.get("frames_without_truth")
    if missing:
        log.warning("%s: %d of %d frames have no pose in %s; the figures judge the %d that do", path, missing,
                    missing + figures["frames"], truth_path, figures["frames"])
    return figures


def _check_selected(selected: int, lines: int, frames: FrameRange, path) -> None:
    """InputError when ``frames`` selects none of the ``lines`` of a frames or poses file."""
    if selected == 0 and lines > 0:
        raise InputError(f"{path}: --frames {frames} selects no line (the file has {lines})")
