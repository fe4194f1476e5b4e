"""Plain-text summaries of the library runs' results, as the command line prints them (kept
here so that cli.py only parses, calls and prints, and so a script can print the same lines)."""

from __future__ import annotations

import json

import numpy as np

from .runs.accumulation import TRACKED_PASSES


def info_lines(summary, object_frame: str, camera_frame: str) -> list[str]:
    """``accum info``'s summary of a ``RecordingInfo``."""
    if summary.topics_only:   # a topic is missing (the error that follows says which, and what to try)
        return [f"recording    {summary.path}", f"tf frames    {', '.join(summary.tf_frames) or 'none'}",
                *_topic_lines(summary.topics)]
    intr = summary.intrinsics
    seconds = ((summary.last_ns or 0) - (summary.first_ns or 0)) * 1e-9
    offset = f", left/right {summary.stereo_offset_ms:.3f} ms apart" if summary.stereo_offset_ms is not None else ""
    lines = [f"recording    {summary.path}",
             f"frames       {summary.stereo_frames} stereo frames over {seconds:.3f} s, "
             f"{summary.unpaired_images} unpaired images{offset}"]
    paired = 2 * summary.stereo_frames
    if summary.unpaired_images > 0.1 * (paired + summary.unpaired_images) and summary.stereo_offset_ms:
        # unsynchronised cameras: a tolerance above nearly every measured offset
        tolerance = summary.pairing_tolerance_ms   # at least 1, set wherever an offset was measured
        lines.append(f"pairing      {summary.unpaired_images} images found no partner within the pairing tolerance: "
                     f"if the two cameras are not synchronised, try --tolerance-ms {tolerance}")
    if summary.lost_bytes:
        lines.append(f"damage       {summary.lost_bytes} bytes could not be read (truncated or damaged)")
    if intr:
        kind = "rectified" if summary.rectified_input else f"raw ({summary.distortion_model}), rectified by accum"
        lines += [f"images       {intr.width}x{intr.height} {summary.image_encoding}, {kind}",
                  f"calibration  fx {intr.fx:.2f} px, fy {intr.fy:.2f} px, cx {intr.cx:.2f}, cy {intr.cy:.2f}, "
                  f"baseline {intr.baseline * 1000:.2f} mm ({summary.calibrations} message(s))"]
        if summary.size_problem:
            lines.append(f"problem      {summary.size_problem}")
    lines.append(f"poses        {object_frame} in {camera_frame}: {summary.frames_with_pose}/{summary.stereo_frames}"
                 " frames")
    lines += [f"             {count} frame(s): {reason}" for reason, count in summary.pose_problems]
    lines.append(f"tf frames    {', '.join(summary.tf_frames) or 'none'}")
    return lines + _topic_lines(summary.topics)


def _topic_lines(topics) -> list[str]:
    width = max([32] + [len(topic) + 1 for topic, _, _ in topics])
    kinds = max([28] + [len(schema) + 1 for _, schema, _ in topics])
    return ["topics", *(f"  {topic:<{width}} {schema:<{kinds}} {count if count is not None else '?':>6}"
                        for topic, schema, count in topics)]


def info_json(summary) -> str:
    doc = {k: v for k, v in summary.__dict__.items() if k != "intrinsics"}
    doc["intrinsics"] = summary.intrinsics.as_dict() if summary.intrinsics else None
    return json.dumps(doc, indent=1)


def _times(times, frames: int, label: str = "time per frame") -> str:
    return f"{label}: " + ", ".join(f"{k} {1000 * v / max(frames, 1):.1f} ms" for k, v in times.seconds.items())


def extraction_lines(result) -> list[str]:
    return [f"{result.frames} frames: {result.per_frame('segments'):.0f} 3D segments per frame from "
            f"{result.per_frame('left_2d'):.0f} left 2D segments ({result.per_frame('critical'):.0f} critical, "
            f"{result.per_frame('critical_3d'):.0f} of them triangulated from their ends, "
            f"{result.per_frame('unmatched'):.0f} unmatched), {result.pairs_per_second:.1f} pairs/s",
            _times(result.times, result.frames)]


def accumulation_lines(result, motion: str = "gripper") -> list[str]:
    skipped = sum(result.skipped.values())
    lines = [f"{result.frames} frames accumulated" + (f", {skipped} skipped without a pose" if skipped else "")
             + f": model of {len(result.model)} segments, {result.accepted} accepted (confidence >= 0.5)",
             _times(result.times, result.frames,
                    f"time per frame, its {TRACKED_PASSES} passes together" if motion == "tracked"
                    else "time per frame")]
    if any("outside_box" in row for row in result.rows):
        outside, kept = (sum(row.get(key, 0) for row in result.rows) for key in ("outside_box", "observed"))
        lines.append(f"box: {outside} of {outside + kept} 3D segments lay outside it and were dropped")
    if any("across_frames" in row for row in result.rows):
        across, replacing, observed = (sum(row.get(key, 0) for row in result.rows)
                                       for key in ("across_frames", "across_frames_replacing", "observed"))
        lines.append(f"lines across frames: {across} of the {observed} 3D segments ({replacing} in place of a stereo "
                     "segment less sure of its direction)")
    if motion == "tracked":
        lines.append(f"tracked motion: {result.refined_frames} of {result.frames} frames used a refined pose")
    if result.scores:
        s = result.scores
        lines.append(f"against the truth: precision {s['precision']:.3f}, completeness {s['completeness']:.3f}, "
                     f"background {s['background']:.3f}")
        if s.get("judge_by_surface"):
            lines.append("(by the edges: this truth has faces, by which `accum eval MODEL TRUTH` judges "
                         "precision and background on the object's surface)")
    return lines


def tracking_lines(result) -> list[str]:
    n = result.frames
    residual = (f"median residual {result.median_residual_px:.2f} px" if np.isfinite(result.median_residual_px)
                else "no residual (no frame tracked)")
    lines = [f"{n} frames: {result.tracked} tracked ({result.tracked / max(n, 1):.0%}), {residual}, "
             f"{result.frames_per_second:.1f} frames/s"]
    if result.params is not None:
        lines.append(f"limits from {result.limits_source}: RMS <= {result.params.max_rms_px:.2f} px, inlier share >= "
                     f"{result.params.min_inlier_fraction:.2f}")
    return lines


def figures_lines(figures: dict) -> list[str]:
    """``accum eval``'s figures, one per line."""
    def cell(value):
        if isinstance(value, float):
            return f"{value:.4f}" if np.isfinite(value) else "-"
        return value
    return [f"{key:<28} {cell(value)}" for key, value in figures.items()]
