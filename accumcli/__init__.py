"""accum: accumulate 3D line-segment object models from stereo recordings.

Conventions (one page, used everywhere):

- ``T_a_b`` is a (4, 4) float64 homogeneous transform, the pose of frame b in
  frame a; it maps points expressed in b into a: ``p_a = T_a_b @ p_b``.
- Points are rows: ``(N, 3) float64``, metres. Segments are (center, unit
  direction, length).
- Camera frames are optical: x right, y down, z forward.
- Quaternions are ``quat_xyzw`` and only at file boundaries; inside, rotations
  are 3x3 matrices.
- Time is integer nanoseconds; seconds only for display.
- Pixel coordinates are ``(u, v) = (x, y)`` = (column, row); arrays are indexed
  ``[row, col]``.
"""

__version__ = "0.1.0"
