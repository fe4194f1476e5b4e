"""The generic accumulation core (with 3D points, to prove it is generic) and the
line-segment entity type's visibility test and merge."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from accumcli.accumulate import Accumulator, UpdateRule, one_to_one
from accumcli.geometry import invert, make_transform, transform_points
from accumcli.line_model import FrameContext, LineSegmentType
from accumcli.recording import StereoIntrinsics
from accumcli.segments import Segments


@dataclass
class Points:
    xyz: np.ndarray  # (N, 3) metres
    weight: np.ndarray


class PointType:
    """3D points: Euclidean distance under 2 mm, rigid transform, weighted mean."""

    radius = 0.002

    def size(self, p):
        return len(p.xyz)

    def select(self, p, index):
        return Points(p.xyz[index], p.weight[index])

    def concatenate(self, a, b):
        return Points(np.vstack([a.xyz, b.xyz]), np.concatenate([a.weight, b.weight]))

    def transform(self, p, T):
        return Points(transform_points(T, p.xyz), p.weight)

    def correspondences(self, model, observed):
        if not len(model.xyz) or not len(observed.xyz):
            return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
        pairs = cKDTree(observed.xyz).sparse_distance_matrix(cKDTree(model.xyz), self.radius, output_type="ndarray")
        return pairs["j"].astype(int), pairs["i"].astype(int), pairs["v"] / self.radius

    def same(self, model, i, j):
        distance = np.linalg.norm(model.xyz[i] - model.xyz[j], axis=1)
        return distance <= self.radius / 2, distance

    def merge(self, model, observed, mi, oi, context):
        xyz, w = model.xyz.copy(), model.weight.copy()
        total = w[mi] + observed.weight[oi]
        xyz[mi] = (xyz[mi] * w[mi, None] + observed.xyz[oi] * observed.weight[oi, None]) / total[:, None]
        w[mi] = total
        return Points(xyz, w)

    def observe(self, observed, context):
        return observed

    def expected(self, model, context):
        return np.ones(len(model.xyz), bool)


def test_core_is_generic_object_points_stay_background_fades():
    rng = np.random.default_rng(0)
    object_points = rng.uniform(-0.05, 0.05, (40, 3))
    background = rng.uniform(-0.3, 0.3, (200, 3)) + [0, 0, 1.0]   # static in the camera frame
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    history = []
    for k in range(15):
        T_camera_object = make_transform(Rotation.from_rotvec([0, np.radians(8 * k), 0]).as_matrix(), [0, 0, 0.5])
        seen = rng.random(len(object_points)) < 0.8
        obj = transform_points(T_camera_object, object_points[seen]) + rng.normal(0, 0.0003, (seen.sum(), 3))
        bg = background[rng.random(len(background)) < 0.8]
        observed = Points(np.vstack([obj, bg]), np.ones(len(obj) + len(bg)))
        stats = acc.update(observed, invert(T_camera_object))
        history.append(stats)
    accepted = acc.entities.xyz[acc.confidence >= 0.5]
    distance, _ = cKDTree(object_points).query(accepted)
    assert len(accepted) >= 38                     # nearly every object point
    assert np.all(distance < 0.001)                # and nothing of the background
    assert history[-1].confirmed >= 25 and history[-1].new > 100


def test_one_to_one_is_a_matching_that_keeps_mutual_best_pairs():
    rng = np.random.default_rng(1)
    a, b = rng.integers(0, 30, 200), rng.integers(0, 30, 200)
    cost = rng.random(200)
    chosen = one_to_one(a, b, cost)
    assert len(set(a[chosen])) == len(chosen) == len(set(b[chosen]))
    best_a = {x: np.argmin(np.where(a == x, cost, np.inf)) for x in set(a)}
    best_b = {x: np.argmin(np.where(b == x, cost, np.inf)) for x in set(b)}
    mutual = {k for k in best_a.values() if best_b[b[k]] == k}
    assert mutual <= set(chosen.tolist())


INTR = StereoIntrinsics(600.0, 600.0, 319.5, 239.5, 0.08, 640, 480)


def _one_segment(direction=(0.0, 1.0, 0.0)) -> Segments:
    return Segments("gripper", np.zeros((1, 3)), np.array([direction]), np.array([0.012]), np.array([0.9]),
                    np.ones(1, np.int64), {"sigma_depth_m": np.array([0.001])})


def test_expected_only_where_the_segment_should_be_seen():
    kind = LineSegmentType()
    T_front = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    model = kind.observe(_one_segment(), FrameContext(T_front, INTR))   # seen from the front
    assert kind.expected(model, FrameContext(T_front, INTR))[0]
    turned = make_transform(Rotation.from_rotvec([0, np.radians(80), 0]).as_matrix(), [0.0, 0.0, 0.5])
    assert not kind.expected(model, FrameContext(turned, INTR))[0]        # turned away: not punished
    aside = make_transform(np.eye(3), [0.5, 0.0, 0.5])
    assert not kind.expected(model, FrameContext(aside, INTR))[0]         # outside the images
    horizontal = kind.observe(_one_segment((1.0, 0.0, 0.0)), FrameContext(T_front, INTR))
    assert not kind.expected(horizontal, FrameContext(T_front, INTR))[0]  # on the critical plane


def test_merge_trusts_each_view_across_and_covers_the_union_along_the_line():
    kind = LineSegmentType()
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    model = kind.observe(_one_segment(), FrameContext(T, INTR))
    observed = _one_segment()
    observed.centers = np.array([[0.0003, 0.004, 0.002]])   # 2 mm deeper (uncertain), 4 mm along y
    observed = kind.observe(observed, FrameContext(T, INTR))
    merged = kind.merge(model, observed, np.array([0]), np.array([0]), FrameContext(T, INTR))
    center = merged.centers[0]
    assert abs(center[2] - 0.001) < 0.0002      # depth: equal information, the average
    assert 0.0001 < center[0] < 0.0002          # across, in x: the average too
    # along y: the union of [-6, 6] mm and [-2, 10] mm, centred on its middle: 4 mm shift, 2 mm move
    assert abs(center[1] - 0.002) < 1e-9 and abs(merged.lengths[0] - 0.016) < 1e-9


def test_merge_trims_the_union_to_max_extent_at_both_ends():
    kind = LineSegmentType()                    # max_extent 2: at most 24 mm for 12 mm observations
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    model = kind.observe(_one_segment(), FrameContext(T, INTR))
    observed = _one_segment()
    observed.centers = np.array([[0.0, 0.020, 0.0]])        # union [-6, 26] mm: 32 mm, trimmed by 4 at each end
    observed = kind.observe(observed, FrameContext(T, INTR))
    merged = kind.merge(model, observed, np.array([0]), np.array([0]), FrameContext(T, INTR))
    assert abs(merged.centers[0, 1] - 0.010) < 1e-9 and abs(merged.lengths[0] - 0.024) < 1e-9


def _points_run(seen_every: int, frames: int):
    """One point, always expected, observed in frames 0 and 1 (accepted) and then in one frame out of
    ``seen_every``: its confidence history."""
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    point = Points(np.zeros((1, 3)), np.ones(1))
    nothing = Points(np.zeros((0, 3)), np.zeros(0))
    history = []
    for k in range(frames):
        acc.update(point if k < 2 or k % seen_every == 0 else nothing, np.eye(4))
        history.append(acc.confidence.tolist())
    return history


def test_update_rule_figures_of_the_module_docstring():
    rule = UpdateRule()
    assert abs(rule.hit - np.log(5)) < 1e-12 and abs(rule.miss - np.log(5 / 9)) < 1e-12
    # a new entity (0.25), missed twice: 0.16, then 0.09 < floor: pruned
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    history = []
    for k in range(3):
        acc.update(Points(np.zeros((1 - min(k, 1), 3)), np.ones(1 - min(k, 1))), np.eye(4))
        history.append(acc.confidence.tolist())
    assert abs(history[0][0] - 0.25) < 1e-12 and abs(history[1][0] - 0.156) < 0.001 and history[2] == []
    # accepted at its first confirmation: 0.625
    assert abs(_points_run(seen_every=1, frames=2)[1][0] - 0.625) < 1e-9
    # survives when seen in a third of the frames that should show it (break-even is 0.27), not a fifth
    assert _points_run(seen_every=3, frames=30)[-1][0] > 0.9
    assert _points_run(seen_every=5, frames=30)[-1] == []
