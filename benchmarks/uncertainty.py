"""``make uncertainty``: are the extracted segments' sigmas honest? Read after ``make suite``.

For the single-frame 3D segments of the suite's frames files (out/bench/suite/), the actual errors
against their nearest truth edge: the direction error (degrees) against ``sigma_direction_rad``, of
the segments whose centre lies within ``NEAR_M`` of the edge; and the offset along the viewing ray
(mm) against ``sigma_depth_m``, of the segments within ``DEPTH_REACH_M`` of an edge, within 10
degrees of it and within ``ACROSS_RAY_M`` of it across the ray (chosen by what stereo measures well,
so that the depth error itself does not decide which segments are counted). Per sigma bin, pooled over the rows: count, median and 90th
percentile of the error, and the share beyond the evaluation's 10 degrees (4 mm). For a Gaussian
error the median of |error| is 0.67 sigma: a bin whose median error sits far above that says the
sigma is too small, which the accumulator's gates and weights then trust. Then per recording the
median signed depth offset (positive: farther from the cameras than the truth): a calibration or a
truth that is off shows there as an offset shared by every segment (the teabox: -3.0 mm against its
peer tracker's poses, every other row within 0.1 mm).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import CACHE  # noqa: E402

NEAR_M = 0.004
DEPTH_REACH_M = 0.03
ACROSS_RAY_M = 0.0015
DIRECTION_BINS_DEG = (0, 1, 2, 4, 6, 10, 20, 90)
DEPTH_BINS_MM = (0, 0.25, 0.5, 1, 2, 4, 1000)


def errors(frames_file: str, truth_file: str) -> np.ndarray:
    """(N, 4): direction error deg, sigma deg, depth offset mm, sigma mm of the near segments."""
    from accumcli.evaluate import EdgeSamples, Tolerances, _point_edge_distance
    from accumcli.geometry import invert, rotate_vectors
    from accumcli.model_io import read_frames, read_truth

    truth = read_truth(truth_file)
    edges = EdgeSamples.of(truth, Tolerances())
    edge_dir = (edges.b - edges.a) / np.linalg.norm(edges.b - edges.a, axis=1, keepdims=True)
    rows = []
    for t_ns, segments, _ in read_frames(frames_file):
        T = truth.pose_at(int(t_ns))
        if T is None or len(segments) == 0 or "sigma_direction_rad" not in segments.extra:
            continue
        local = segments.transformed(invert(T), "object")
        distances = _point_edge_distance(local.centers, edges.a, edges.b)
        nearest = distances.argmin(axis=1)
        distance = distances[np.arange(len(local)), nearest]
        near = distance <= NEAR_M
        direction_error = np.degrees(np.arccos(np.clip(np.abs(np.sum(local.directions * edge_dir[nearest], 1)), 0, 1)))
        offset = local.centers - edges.a[nearest]
        offset -= np.sum(offset * edge_dir[nearest], 1)[:, None] * edge_dir[nearest]   # across the edge
        ray = segments.centers / np.linalg.norm(segments.centers, axis=1, keepdims=True)
        offset_camera = rotate_vectors(T, offset)
        depth_error = np.sum(offset_camera * ray, axis=1)
        across_ray = np.linalg.norm(offset_camera - depth_error[:, None] * ray, axis=1)
        on_ray = (distance <= DEPTH_REACH_M) & (direction_error <= 10) & (across_ray <= ACROSS_RAY_M)
        rows.append(np.column_stack([np.where(near, direction_error, np.nan),
                                     np.degrees(segments.extra["sigma_direction_rad"]),
                                     np.where(on_ray, 1000 * depth_error, np.nan),
                                     1000 * segments.extra["sigma_depth_m"]])[near | on_ray])
    return np.concatenate(rows) if rows else np.zeros((0, 4))


def table(error: np.ndarray, sigma: np.ndarray, bins, unit: str, limit: float) -> list[str]:
    lines = [f"| sigma ({unit}) | segments | median error | 90 % error | beyond {limit:g} {unit} |", "|---|---|---|---|---|"]
    for lo, hi in zip(bins[:-1], bins[1:]):
        pick = (sigma >= lo) & (sigma < hi) & np.isfinite(error)
        if pick.any():
            e = np.abs(error[pick])
            lines.append(f"| {lo:g} - {hi:g} | {pick.sum()} | {np.median(e):.2f} | {np.percentile(e, 90):.2f} | "
                         f"{(e > limit).mean():.2f} |")
    return lines


def main() -> int:
    from suite import real_and_independent_rows, simulated_rows

    found = {}      # recording name -> its errors
    for row in simulated_rows() + real_and_independent_rows():
        frames = CACHE / "suite" / f"{row.name}.frames.jsonl"
        if frames.exists():
            found[row.name] = errors(str(frames), row.truth)
    if not found:
        print("no frames files in out/bench/suite/: run make suite first", file=sys.stderr)
        return 1
    e = np.concatenate(list(found.values()))
    print(f"{len(found)} recordings: {np.isfinite(e[:, 0]).sum()} segments within {NEAR_M * 1000:g} mm of an edge "
          f"(direction), {np.isfinite(e[:, 2]).sum()} on an edge's viewing rays (depth)\n")
    print("\n".join(table(e[:, 0], e[:, 1], DIRECTION_BINS_DEG, "deg", 10.0)))
    print()
    print("\n".join(table(e[:, 2], e[:, 3], DEPTH_BINS_MM, "mm", 4.0)))
    print("\n| recording | segments on rays | median signed depth offset (mm) |\n|---|---|---|")
    for name, rows in found.items():
        depth = rows[np.isfinite(rows[:, 2]), 2]
        print(f"| {name} | {len(depth)} | {np.median(depth):+.2f} |" if len(depth) else f"| {name} | 0 | - |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
