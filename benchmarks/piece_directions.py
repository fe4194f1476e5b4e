"""How far single-frame 3D directions are off, by how the piece was triangulated (part of ``make uncertainty``).

For every non-critical 3D piece of the devset recordings (``../shared/data/devset``, all frames; the
tracking one left out) whose centre lies within 4 mm of a truth edge: the share more than 10 degrees
off that edge (the evaluation's limit) and the median error, for pieces on a *stretch* of three or
more (``stereo.triangulate`` fits disparity along the left/right line pair they share) and for the
others, binned by the span of their lines (the shorter of the left and right line's extent, px).
Why: the largest loss of the scoreboard's second table is the edge length matched but wrong in 3D,
and this says which pieces make it: with an 8 cm baseline at 0.55-0.8 m the two planes of a short
line meet at a few degrees, so the depth tilt of a piece alone on its stretch is its lines' angle
error times about ten.

A third table: the angle error of the 2D lines themselves (each piece's left and right line against
the projection of its edge in that image, by the line's span): how sure the back-projected planes are
(``stereo``'s plane sigma, compared in the last column), and so what limits a lone piece's tilt.

A second table: the disparity error of the same pieces (px: the piece's disparity against the one of
the point where its centre's viewing ray passes nearest the edge), by the left piece's angle to the
image rows, against the sigma the piece claims (``sigma_depth_m`` in disparity): is the depth
uncertainty honest? A piece's disparity comes from where its lines cross a row, so an error across
the lines of e px moves it by e / sin(angle): near the critical angle that is four to seven times e.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import ROOT  # noqa: E402

DEVSET = ROOT.parent / "shared" / "data" / "devset"
NEAR_M = 0.004
SPAN_BINS_PX = (0, 15, 25, 40, 10_000)
ANGLE_BINS_DEG = (0, 12, 20, 30, 50, 91)
LINE_SPAN_BINS_PX = (0, 15, 20, 27, 35, 50, 10_000)


def pieces(recording: Path, truth_file: Path) -> np.ndarray:
    """(N, 10): direction error deg, stretch size, line span px, disparity error px, claimed disparity
    sigma px, the left piece's angle to the image rows deg, the left and right lines' angle errors deg
    (signed, against the edge's projection) and spans px, of the on-edge non-critical pieces."""
    from accumcli.evaluate import _point_edge_distance
    from accumcli.extract import extract_frame
    from accumcli.geometry import invert, transform_points
    from accumcli.model_io import read_truth
    from accumcli.recording import Recording
    from accumcli.stereo import line_span, stretch_ids

    truth = read_truth(str(truth_file))
    edge_dir = (truth.b - truth.a) / np.linalg.norm(truth.b - truth.a, axis=1, keepdims=True)
    rows = []
    with Recording(str(recording)) as rec:
        for frame in rec.frames():
            T = truth.pose_at(frame.timestamp_ns)
            out = extract_frame(frame)
            stereo = out.right_index >= 0            # -1: a critical piece, triangulated from its run's ends
            if T is None or not stereo.any():
                continue
            left, right = out.left, out.right
            li, ri = out.left_index[stereo], out.right_index[stereo]
            stretch = stretch_ids(left, right, li, ri)
            size = np.bincount(stretch)[stretch]                                  # pieces on each one's stretch
            camera = out.segments.select(np.flatnonzero(stereo))
            local = camera.transformed(invert(T), "object")
            distances = _point_edge_distance(local.centers, truth.a, truth.b)
            nearest = distances.argmin(axis=1)
            near = distances[np.arange(len(local)), nearest] <= NEAR_M
            error = np.degrees(np.arccos(np.clip(np.abs(np.sum(local.directions * edge_dir[nearest], 1)), 0, 1)))
            fB = frame.intrinsics.fx * frame.intrinsics.baseline
            depth = _depth_on_edge(camera.centers, transform_points(T, truth.a[nearest]),
                                   transform_points(T, truth.b[nearest]))
            disparity_error = camera.extra["disparity_px"] - fB / depth
            claimed = camera.extra["sigma_depth_m"] * fB / camera.centers[:, 2] ** 2
            angle = np.degrees(np.arcsin(np.clip(np.abs(left.directions[li, 1]), 0, 1)))
            a, b = transform_points(T, truth.a[nearest]), transform_points(T, truth.b[nearest])
            line_errors = [_angle_error(side.line_direction[index], a, b, frame.intrinsics, shift)
                           for side, index, shift in ((left, li, 0.0), (right, ri, 1.0))]
            rows.append(np.column_stack([error, size, np.minimum(line_span(left, li), line_span(right, ri)),
                                         disparity_error, claimed, angle, *line_errors, line_span(left, li),
                                         line_span(right, ri)])[near])
    return np.concatenate(rows) if rows else np.zeros((0, 10))


def _angle_error(direction: np.ndarray, a: np.ndarray, b: np.ndarray, intr, right: float) -> np.ndarray:
    """(N,) deg, signed: the image lines' ``direction`` (N, 2) against the projection of the edges a, b
    (N, 3, camera frame) in the left image (``right`` 0) or the right one (1); nan where an end is
    behind the camera."""
    def project(p):
        return np.where((p[:, 2] > 1e-6)[:, None], intr.project(p)[int(right)], np.nan)
    with np.errstate(divide="ignore", invalid="ignore"):
        edge = project(b) - project(a)
        edge /= np.linalg.norm(edge, axis=1, keepdims=True)
    cross = direction[:, 0] * edge[:, 1] - direction[:, 1] * edge[:, 0]
    return np.degrees(np.arcsin(np.clip(cross * np.where(np.sum(direction * edge, axis=1) >= 0, 1.0, -1.0), -1, 1)))


def _depth_on_edge(centers: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) m: the depth where the viewing ray through each centre (N, 3, camera frame) passes nearest
    the line of its edge a, b (N, 3, camera frame)."""
    from accumcli.stereo import nearest_to_rays

    ray = centers / np.linalg.norm(centers, axis=1, keepdims=True)
    edge = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    t, _ = nearest_to_rays(a, edge, ray)
    return np.sum((a + t[:, None] * edge) * ray, axis=1) * ray[:, 2]   # that point's place along the ray


def main() -> int:
    files = sorted(p for p in DEVSET.glob("*.mcap") if "track" not in p.name) if DEVSET.is_dir() else []
    if not files:
        print(f"no devset at {DEVSET}: nothing to measure")
        return 0
    e = np.concatenate([pieces(p, p.with_suffix(".truth.json")) for p in files])
    print(f"{len(e)} non-critical pieces within {NEAR_M * 1000:.0f} mm of an edge, {len(files)} devset recordings\n")
    print("| pieces | line span px | count | more than 10 deg off | median error deg |")
    print("|---|---|---|---|---|")
    groups = [("on a stretch of 3+", e[:, 1] >= 3, 0, SPAN_BINS_PX[-1])]
    groups += [("alone or in two", e[:, 1] < 3, lo, hi) for lo, hi in zip(SPAN_BINS_PX, SPAN_BINS_PX[1:])]
    for label, kind, lo, hi in groups:
        rows = e[kind & (e[:, 2] >= lo) & (e[:, 2] < hi)]
        if len(rows):
            span = "any" if hi == SPAN_BINS_PX[-1] and lo == 0 else f"{lo}-{hi}" if hi < SPAN_BINS_PX[-1] else f">= {lo}"
            print(f"| {label} | {span} | {len(rows)} | {np.mean(rows[:, 0] > 10):.2f} | {np.median(rows[:, 0]):.1f} |")
    print("\n| pieces | angle to the rows deg | count | disparity error px (1.4826 x median abs) | 90 % of abs error | "
          "claimed sigma px (median) |\n|---|---|---|---|---|---|")
    for label, kind in (("on a stretch of 3+", e[:, 1] >= 3), ("alone or in two", e[:, 1] < 3)):
        for lo, hi in zip(ANGLE_BINS_DEG, ANGLE_BINS_DEG[1:]):
            rows = e[kind & (e[:, 5] >= lo) & (e[:, 5] < hi)]
            if len(rows):
                print(f"| {label} | {lo}-{hi} | {len(rows)} | {1.4826 * np.median(np.abs(rows[:, 3])):.3f} | "
                      f"{np.percentile(np.abs(rows[:, 3]), 90):.3f} | {np.median(rows[:, 4]):.3f} |")
    print("\n| image | line span px | count | angle error deg (1.4826 x median abs. deviation) | 90 % of abs error | "
          "stereo's plane sigma deg |\n|---|---|---|---|---|---|")
    from accumcli.stereo import StereoParams, plane_sigma_deg

    params = StereoParams()
    for label, error, span in (("left", e[:, 6], e[:, 8]), ("right", e[:, 7], e[:, 9])):
        for lo, hi in zip(LINE_SPAN_BINS_PX, LINE_SPAN_BINS_PX[1:]):
            chosen = (span >= lo) & (span < hi) & np.isfinite(error)
            rows = error[chosen]
            if len(rows):   # the plane sigma that stereo claims at the bin's median span
                claimed = float(plane_sigma_deg(np.median(span[chosen]), params))
                print(f"| {label} | {lo}-{hi if hi < LINE_SPAN_BINS_PX[-1] else ''} | {len(rows)} | "
                      f"{1.4826 * np.median(np.abs(rows - np.median(rows))):.2f} | {np.percentile(np.abs(rows), 90):.2f} | "
                      f"{claimed:.2f} |")
    off = e[:, 0] > 10
    difference = np.abs(e[:, 6] - e[:, 7])
    print(f"\nthe left and right lines' angle errors differ by a median of {np.nanmedian(difference[off]):.2f} deg "
          f"for the pieces more than 10 deg off in 3D, {np.nanmedian(difference[~off]):.2f} for the others")
    return 0


if __name__ == "__main__":
    sys.exit(main())
