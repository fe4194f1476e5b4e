"""A held segment takes the model's dominant direction that its view plane holds
(``accumcli.dominant_directions``), and only then."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from accumcli.dominant_directions import DominantParams, covered, dominant_directions
from accumcli.line_model import FrameContext, LineModelParams, LineSegmentType, to_model
from accumcli.segments import Segments
from tests.test_accumulate import INTR, _tilted_towards_camera

Y = np.array([0.0, 1.0, 0.0])
TOWARDS_CAMERA = np.array([0.0, 0.0, -1.0])     # the camera at z = -0.5 m, object frame


def _turned(direction, axis, deg) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(deg) * np.asarray(axis, float)).apply(direction)


def _box_edges(y_directions=4, offset_deg=0.0):
    """Accepted segments (centres (M, 3) m, directions (M, 3)): 4 along x, ``y_directions`` along y
    (turned by ``offset_deg`` towards the camera, within the held segment's view plane), 4 along z; each
    direction about 0.5 degrees off its axis, 20 mm long, all at least 30 mm from the origin."""
    rng = np.random.default_rng(1)
    centers, directions = [], []
    for axis, n in ((np.array([1.0, 0, 0]), 4), (_turned(Y, [1, 0, 0], -offset_deg), y_directions),
                    (np.array([0, 0, 1.0]), 4)):
        for k in range(n):
            centers.append(np.array([0.03 + 0.01 * k, -0.03, 0.04 * (k % 2)]))
            directions.append(_turned(axis, rng.normal(size=3), 0.5))
    return np.array(centers), np.array(directions)


def _case(held_sigma_deg=10.0, tilt_deg=12.0, extra_centers=(), extra_directions=(), **box):
    """A held segment at the origin (y tilted ``tilt_deg`` towards the camera, within its view plane),
    its view direction (1, 3), its sigma (1,) rad, and the shared segments (the box's and the extra ones)."""
    centers, directions = _box_edges(**box)
    centers = np.vstack([centers, np.reshape(extra_centers, (-1, 3))])
    directions = np.vstack([directions, np.reshape(extra_directions, (-1, 3))])
    n = len(centers)
    shared = Segments("gripper", centers, directions, np.full(n, 0.02), np.ones(n), np.ones(n, np.int64))
    tilted = np.cos(np.radians(tilt_deg)) * Y + np.sin(np.radians(tilt_deg)) * TOWARDS_CAMERA
    held = Segments("gripper", np.zeros((1, 3)), tilted[None], np.array([0.02]), np.ones(1), np.ones(1, np.int64))
    return held, TOWARDS_CAMERA[None], np.radians([held_sigma_deg]), shared


def _taken(case, p=DominantParams()):
    """(taken (1,) bool as ``to_model`` decides, directions (1, 3), their sigma (1,))."""
    held, view, sigma, shared = case
    taken, directions, rms = dominant_directions(held.directions, view, sigma, shared, p)
    return taken & ~covered(held.centers, held.lengths, directions, shared, p), directions, rms


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(np.dot(a, b))))))


def test_a_held_segment_takes_the_dominant_direction_its_view_plane_holds():
    """Tilted 12 degrees in depth and unsure by 10: it takes the y edges' mean direction (within a degree
    of y, its sign kept, in its own view plane) and a sigma from their scatter, whichever sign the
    shared segments' directions carry."""
    for flipped in (False, True):
        held, view, sigma, shared = _case()
        if flipped:
            shared.directions[4:6] *= -1.0         # two of the four along y
        taken, directions, rms = _taken((held, view, sigma, shared))
        assert taken[0] and _angle_deg(directions[0], Y) < 1.0 and np.dot(directions[0], held.directions[0]) > 0
        assert abs(np.dot(directions[0], np.cross(view[0], held.directions[0]))) < 1e-9
        assert 0.0 < rms[0] < np.radians(2.0)


def test_what_the_dominant_directions_do_not_decide():
    """Not taken: a turn beyond 2 sigmas (a segment sure to 3 degrees, turned by 12), a direction shared by
    one accepted segment only, a direction 30 degrees off every accepted one, a stretch an accepted
    parallel segment 5 mm away already covers, a plane holding two directions alike (y and y turned 16
    degrees within it), a shared direction 8 degrees out of the plane, a segment 10 degrees off its
    viewing ray (its plane unsure); nor with fewer shared segments than ``min_segments``. Taken: beside a
    parallel segment 5 mm across but past its end, or one 5 mm away crossing at 90 degrees."""
    four = np.tile([0.06, 0.03, 0.0], (4, 1)) + np.arange(4)[:, None] * [0.0, 0.0, 0.01]
    cases = [dict(held_sigma_deg=3.0), dict(y_directions=1), dict(tilt_deg=30.0),
             dict(extra_centers=[0.005, 0.0, 0.0], extra_directions=Y),
             dict(extra_centers=four, extra_directions=np.tile(_turned(Y, [1, 0, 0], -16.0), (4, 1))),
             dict(y_directions=0, extra_centers=four, extra_directions=np.tile(_turned(Y, [0, 0, 1], 8.0), (4, 1))),
             dict(tilt_deg=80.0)]          # 10 degrees off the ray; the box's z edges lie in its plane, 10 off it
    for case in cases:
        assert not _taken(_case(**case))[0].any(), case
    assert _taken(_case(tilt_deg=80.0), DominantParams(min_plane_sine=0.0))[0][0]   # the plane's test decides
    for beside in (dict(extra_centers=[0.0, 0.06, 0.005], extra_directions=Y),
                   dict(extra_centers=[0.005, 0.0, 0.0], extra_directions=[1.0, 0.0, 0.0])):
        assert _taken(_case(**beside))[0][0], beside
    held, view, sigma, shared = _case()
    assert not _taken((held, view, sigma, shared.select(np.array([4]))))[0].any()
    assert _taken(_case(), DominantParams(share=0.9))[0][0]      # one direction: all of the candidates' length


def test_unsure_observations_take_the_dominant_direction_in_the_running_accumulation():
    """``observations_directed``: of three observations beside the box, the one tilted 12 degrees and
    unsure (10) takes y with a sigma of at least ``observation_sigma_deg``; one sure to 1 degree (under
    ``unsure_deg``) and one 30 degrees off are left as they were."""
    from accumcli.dominant_directions import observations_directed

    _, _, _, shared = _case()
    tilted = np.cos(np.radians(12.0)) * Y + np.sin(np.radians(12.0)) * TOWARDS_CAMERA
    far = np.cos(np.radians(30.0)) * Y + np.sin(np.radians(30.0)) * TOWARDS_CAMERA
    observed = Segments("gripper", np.zeros((3, 3)), np.array([tilted, tilted, far]), np.full(3, 0.02), np.ones(3),
                        np.ones(3, np.int64), {"sigma_direction_rad": np.radians([10.0, 1.0, 10.0])})
    out = observations_directed(observed, np.tile(TOWARDS_CAMERA, (3, 1)), shared, DominantParams())
    assert _angle_deg(out.directions[0], Y) < 1.0 and np.isclose(out.extra["sigma_direction_rad"][0], np.radians(4.0))
    assert np.array_equal(out.directions[1:], observed.directions[1:])
    assert np.array_equal(out.extra["sigma_direction_rad"][1:], observed.extra["sigma_direction_rad"][1:])
    assert np.array_equal(observed.directions[0], tilted)          # the input is left as it was
    T, _ = _tilted_towards_camera(0.0, 12.0)                         # the same camera, as the accumulation sees it
    for params, expected in ((LineModelParams(), 0.0), (LineModelParams(dominant=DominantParams(observations=False)), 12.0)):
        entity = LineSegmentType(params).observe(observed, FrameContext(T, INTR, shared=shared))
        assert abs(_angle_deg(entity.directions[0], Y) - expected) < 1.0


def test_the_written_model_accepts_a_held_segment_by_the_dominant_direction_unless_told_not_to():
    """Through ``to_model``: a segment along y seen from one camera, tilted 12 degrees towards it and
    unsure (10 degrees), is held back alone; beside five sure segments along y seen from two aspects it
    is accepted along y and marked ``direction_dominant``. It stays held with ``LineModelParams.dominant``
    None, and where the five were seen from one aspect only (their directions then rest on stereo
    alone, as on a recording that barely turns)."""
    kind = LineSegmentType()
    T, tilted = _tilted_towards_camera(0.0, 12.0)
    centers = np.vstack([np.zeros((1, 3)), [[0.03 + 0.01 * k, 0.0, 0.0] for k in range(5)]])
    directions = np.vstack([tilted, np.tile(Y, (5, 1))])
    n = len(centers)
    segments = Segments("gripper", centers, directions, np.full(n, 0.02), np.full(n, 0.9), np.ones(n, np.int64),
                        {"sigma_depth_m": np.full(n, 0.001),
                         "sigma_direction_rad": np.radians(np.r_[10.0, np.full(n - 1, 0.5)])})
    one_aspect = kind.observe(segments, FrameContext(T, INTR))
    entities = kind.observe(segments, FrameContext(T, INTR))
    entities.extra["views"][1:, 1] = _turned(entities.extra["views"][1:, 0], Y, 30.0)
    confidence, observations = np.full(n, 0.8), np.full(n, 3, np.int64)
    model = to_model(entities, confidence, observations, rules=LineModelParams())
    assert model.accepted.all() and model.extra["direction_dominant"].tolist() == [True] + [False] * (n - 1)
    assert _angle_deg(model.directions[0], Y) < 0.5 and not model.extra["direction_held"].any()
    for off in (to_model(entities, confidence, observations, rules=LineModelParams(dominant=None)),
                to_model(one_aspect, confidence, observations, rules=LineModelParams())):
        assert not off.accepted[0] and off.extra["direction_held"][0] and not off.extra["direction_dominant"].any()
        assert _angle_deg(off.directions[0], Y) > 11.0 and off.accepted[1:].all()
