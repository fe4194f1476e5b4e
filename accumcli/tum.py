"""Poses in the TUM trajectory format, which evo (``evo_traj tum``, ``evo_ape tum``) and most
SLAM tools read: one line per pose, ``timestamp tx ty tz qx qy qz qw``, the timestamp in seconds
and the pose ``T_parent_child`` (here T_camera_object) in metres and a unit quaternion.

Only poses with status ``tracked`` are written (a TUM file has no place for a status or a gap).
The timestamp has nine decimals, so nanoseconds survive the round trip.
"""

from __future__ import annotations

import numpy as np

from .atomic import opened
from .geometry import quat_from_transform


def write_poses_tum(path, track, only_tracked: bool = True) -> int:
    """Write ``track`` (a ``PoseTrack``) as TUM to a path (atomically) or an open text file; returns
    the number of poses written."""
    keep = [i for i, T in enumerate(track.poses) if np.isfinite(T).all()
            and (not only_tracked or not track.status or track.status[i] == "tracked")]
    with opened(path) as f:
        f.write(f"# accum poses: T_{track.parent_frame_id}_{track.child_frame_id}; timestamp tx ty tz qx qy qz qw\n")
        for i in keep:
            translation, quat = quat_from_transform(track.poses[i])
            t_ns = int(track.times_ns[i])
            f.write(f"{t_ns // 1_000_000_000}.{t_ns % 1_000_000_000:09d} "
                    + " ".join(f"{x:.9f}" for x in (*translation, *quat)) + "\n")
    return len(keep)
