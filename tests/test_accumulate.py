"""The generic accumulation core (with 3D points, to prove it is generic) and the
line-segment entity type's visibility test and merge."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from accumcli.accumulate import Accumulator, UpdateRule, _sharing, disjoint_pairs, logit, one_to_one
from accumcli.geometry import invert, make_transform, transform_points
from accumcli.line_model import (
    OBSERVATION_ONLY,
    UNSURE_CONFIDENCE,
    FrameContext,
    LineModelParams,
    LineSegmentType,
    direction_known,
    merged_twins,
    planes_from_image,
    sigmas,
    to_model,
)
from accumcli.lines2d import Gradients, Segments2D
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

    def pair_cost(self, a, b):
        distance = np.linalg.norm(a.xyz - b.xyz, axis=1) / self.radius
        return np.where(distance <= 1, distance, np.inf)

    def essentials(self, p):
        return p

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

    def expected(self, model, context, confirmed=None):
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


def _pieces(centers, directions, lengths) -> Segments2D:
    n = len(centers)
    directions = np.asarray(directions, float).reshape(n, 2)
    return Segments2D(np.asarray(centers, float).reshape(n, 2), directions, np.asarray(lengths, float),
                      np.ones(n, np.int8), np.full(n, 50.0), np.arange(n), np.zeros(n), directions)


def test_a_frame_that_shows_the_edge_but_extracted_nothing_along_it_does_not_miss_the_segment():
    """The segment projects to a vertical line at u = 319.5 px. A frame whose image shows an edge
    there but whose extraction gave no 3D segment along it says nothing (the extractor failed, not
    the object); one that extracted a piece there (its 3D segment went to another model segment) or
    whose image is flat there misses it."""
    kind = LineSegmentType()
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    model = kind.observe(_one_segment(), FrameContext(T, INTR))
    edge = np.full((480, 640), 60, np.uint8)
    edge[:, 320:] = 180
    flat = np.full((480, 640), 60, np.uint8)
    along = _pieces([[319.5, 239.5]], [[0.0, 1.0]], [12.0])
    aside = _pieces([[200.0, 239.5]], [[0.0, 1.0]], [12.0])

    def expected(image, extracted):
        return kind.expected(model, FrameContext(T, INTR, left_gradients=Gradients.of(image),
                                                 extracted_left=extracted))[0]

    assert not expected(edge, aside)       # shown, nothing extracted along it: no miss
    assert expected(edge, along)           # extracted there, and it went elsewhere: a miss
    assert expected(flat, aside)           # nothing there to extract: a miss
    without = LineSegmentType(LineModelParams(unextracted_no_miss=False))
    assert without.expected(model, FrameContext(T, INTR, left_gradients=Gradients.of(edge), extracted_left=aside))[0]


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


def _copy(observed: Segments) -> Segments:
    """An observation as extracted (centre, direction, length, confidence, its two sigmas)."""
    return Segments(observed.frame_id, observed.centers.copy(), observed.directions.copy(), observed.lengths.copy(),
                    observed.confidence.copy(), observed.observations.copy(),
                    {"sigma_depth_m": np.array([0.001]), "sigma_direction_rad": np.array([np.radians(6.0)])})


def _tilted_towards_camera(turn_deg: float, tilt_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(T_camera_object of a camera turned ``turn_deg`` about y at 0.5 m, the unit direction y tilted
    ``tilt_deg`` towards that camera: within the plane through it and the y axis, stereo's weak direction)."""
    T = make_transform(Rotation.from_rotvec([0, np.radians(turn_deg), 0]).as_matrix(), [0.0, 0.0, 0.5])
    camera = invert(T)[:3, 3]                                   # in the object frame
    toward = camera - camera[1] * np.array([0.0, 1.0, 0.0])     # across y, towards the camera
    toward /= np.linalg.norm(toward)
    return T, np.cos(np.radians(tilt_deg)) * np.array([0.0, 1.0, 0.0]) + np.sin(np.radians(tilt_deg)) * toward


def test_two_views_planes_pin_the_direction_that_stereo_tilts():
    """A segment along y seen from two views 40 degrees apart about it, each triangulated 15 degrees
    tilted towards its camera (stereo's weak direction, within the plane through the camera and the
    line): with ``view_planes`` (the default) the two planes meet near the true direction; averaging
    keeps the tilt."""
    kind = LineSegmentType()
    views = []
    for turn_deg in (0.0, 40.0):
        T, tilted = _tilted_towards_camera(turn_deg, 15.0)
        segment = _one_segment(tuple(tilted))
        segment.extra["sigma_direction_rad"] = np.array([np.radians(6.0)])
        observed = kind.observe(segment, FrameContext(T, INTR))
        views.append((observed, T))
    first, _ = views[0]
    # one view alone keeps its own (tilted) direction
    assert abs(np.degrees(np.arccos(abs(first.directions[0, 1]))) - 15.0) < 1e-6
    average = LineSegmentType(LineModelParams(view_planes=False))
    averaged = average.merge(average.observe(_copy(first), FrameContext(views[0][1], INTR)),
                             average.observe(_copy(views[1][0]), FrameContext(views[1][1], INTR)),
                             np.array([0]), np.array([0]), FrameContext(views[1][1], INTR))
    assert np.degrees(np.arccos(abs(averaged.directions[0, 1]))) > 10.0    # 14
    merged = kind.merge(first, views[1][0], np.array([0]), np.array([0]), FrameContext(views[1][1], INTR))
    assert np.degrees(np.arccos(abs(merged.directions[0, 1]))) < 2.0     # the two stereo pulls leave 1.7
    assert np.degrees(sigmas(merged)[1][0]) < 2.0               # and the merged segment knows it


def test_merge_trims_the_union_to_max_extent_at_both_ends():
    kind = LineSegmentType()                    # max_extent 3: at most 36 mm for 12 mm observations
    T = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    model = kind.observe(_one_segment(), FrameContext(T, INTR))
    observed = _one_segment()
    observed.centers = np.array([[0.0, 0.030, 0.0]])        # union [-6, 36] mm: 42 mm, trimmed by 3 at each end
    observed = kind.observe(observed, FrameContext(T, INTR))
    merged = kind.merge(model, observed, np.array([0]), np.array([0]), FrameContext(T, INTR))
    assert abs(merged.centers[0, 1] - 0.015) < 1e-9 and abs(merged.lengths[0] - 0.036) < 1e-9


def _turning(k: int) -> np.ndarray:
    """T_camera_object of frame k: the object 0.5 m ahead, turning by 8 degrees a frame."""
    return make_transform(Rotation.from_rotvec([0, np.radians(8 * k), 0]).as_matrix(), [0, 0, 0.5])


def _points_run(seen: set, frames: int, point=(0.03, 0.0, 0.0)):
    """One point of the object (object frame), always expected, observed (in the camera frame) in the
    frames ``seen``, on a turning object: its confidence after every frame ([] once pruned)."""
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    history = []
    for k in range(frames):
        T = _turning(k)
        observed = Points(transform_points(T, np.array([point])), np.ones(1)) if k in seen else \
            Points(np.zeros((0, 3)), np.zeros(0))
        acc.update(observed, invert(T))
        history.append(acc.confidence.tolist())
    return history


def test_update_rule_figures_of_the_module_docstring():
    rule = UpdateRule()
    assert abs(rule.hit - np.log(5)) < 1e-12
    assert abs(rule.confirmation(2.0) - np.log(2.5)) < 1e-12 and rule.confirmation(10.0) == 0.0
    # a miss of an entity never found again costs nothing; of one found every time, log(0.3 / 0.9)
    assert rule.miss(rule.rate(np.array([0]), np.array([5])))[0] == 0.0
    assert abs(rule.miss(rule.rate(np.array([20]), np.array([20])))[0] - np.log(1 / 3)) < 1e-12
    # accepted at its first confirmation (0.625) although nine expected frames missed it before
    assert abs(_points_run({0, 10}, 11)[-1][0] - 0.625) < 1e-9
    # the nine misses after that cost 1.15 in all (rates 0.4 ... 0.11)
    rates = rule.rate(np.ones(9), np.arange(1, 10))
    assert abs(rates[0] - 0.4) < 1e-12 and abs(np.sum(rule.miss(rates)) + 1.154) < 0.001


def test_a_segment_found_in_one_frame_of_ten_survives_and_grows():
    history = _points_run(set(range(0, 40, 10)), 40)
    assert all(h for h in history)                       # never pruned
    assert history[-1][0] > 0.75                         # accepted, and more sure than at 0.625
    # the paper's fixed p_detect of 0.5 prunes it after its second miss (0.25 -> 0.16 -> 0.09)
    fixed = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)),
                        UpdateRule(prior_rate=0.5, prior_views=1e12, p_max=0.5))
    for k in range(3):
        T = _turning(k)
        fixed.update(Points(transform_points(T, np.array([[0.03, 0.0, 0.0]])), np.ones(1)) if k == 0 else
                     Points(np.zeros((0, 3)), np.zeros(0)), invert(T))
    assert len(fixed) == 0


def test_static_background_is_pruned_the_frame_after_it_is_seen_again():
    """A point static in the camera frame, seen in every frame, on an object turning 8 degrees a frame
    about a point 0.5 m ahead: its place in the object frame moves by 0.5 m * 8 deg = 70 mm a frame, far
    beyond the 2 mm gate. N = 1: each entity it creates is contradicted by the next frame (0.25 -> 0.04)
    and pruned, so it is never accepted; the model holds one entity of it, the newest."""
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    background = np.array([[0.1, 0.05, 1.0]])      # camera frame
    for k in range(12):
        T = _turning(k)
        stats = acc.update(Points(background, np.ones(1)), invert(T))
        assert len(acc) == 1 and acc.confidence[0] == 0.25     # only this frame's, new
        assert stats.contradicted == (1 if k else 0) and stats.pruned == (1 if k else 0)
    # without the test (and with the paper's fixed rate) each entity lingers for two misses (0.16, then 0.09)
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)),
                      UpdateRule(static_margin=None, prior_rate=0.5, prior_views=1e12, p_max=0.5))
    for k in range(4):
        acc.update(Points(background, np.ones(1)), invert(_turning(k)))
    assert len(acc) == 2 and sorted(acc.confidence.round(3)) == [0.156, 0.25]


def test_static_evidence_adds_up_over_frames():
    """A static point whose model place always shows something too, 0.4 mm off (cost 0.2 of the 2 mm
    gate) while the point itself is where it stays still (cost 0): no single frame explains it better by
    the margin of 0.25, but the frames together do (0.2 a frame, more than 0.5 by the third): from then
    on it is contradicted (0.25 -> 0.63 -> 0.89 -> 0.53 -> 0.13, then pruned at 0.02); without the sum
    (``static_evidence`` None) it is confirmed every frame."""
    background = np.array([[0.1, 0.05, 1.0]])      # camera frame
    first = transform_points(invert(_turning(0)), background)          # its model place (object frame)
    for evidence, expected in ((0.5, [0.25, 0.625, 0.893, 0.53, 0.132]),
                               (None, [0.25, 0.625, 0.893, 0.977, 0.995, 0.995])):
        acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule(static_evidence=evidence))
        confidence = []
        for k in range(6):
            T = _turning(k)
            beside = transform_points(T, first + [0.0004, 0.0, 0.0]) if k else np.zeros((0, 3))
            weight = np.r_[1.0, np.full(len(beside), 1e-9)]    # merging it leaves the model's point in place
            acc.update(Points(np.vstack([background, beside]), weight), invert(T))
            there = np.linalg.norm(acc.entities.xyz - first, axis=1) < 0.0001   # not a new one at the other
            confidence += list(acc.confidence[there].round(3))
        assert confidence == expected, (evidence, confidence)


def test_an_object_point_gathers_evidence_against_being_static():
    """A point of the turning object, seen every frame where the object takes it and never where it
    would stay still: each frame after its first takes its sum down by 1 (-5 after six frames). A frame
    that then shows something exactly at its still place and the point only 0.4 mm off its model place
    (the distractor of the test above) adds 0.2 and contradicts nothing, where a new entity's sum would
    pass 0.5 in three such frames."""
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    point = np.array([[0.03, 0.0, 0.0]])                                  # object frame
    for k in range(6):
        acc.update(Points(transform_points(_turning(k), point), np.ones(1)), invert(_turning(k)))
    assert len(acc) == 1 and acc.static_sum.tolist() == [-5.0] and acc.confidence[0] > 0.99
    still = transform_points(_turning(0), point)                           # camera frame, as first seen
    beside = transform_points(_turning(6), point + [0.0004, 0.0, 0.0])
    stats = acc.update(Points(np.vstack([still, beside]), np.r_[1.0, 1e-9]), invert(_turning(6)))
    assert stats.contradicted == 0 and abs(acc.static_sum[0] + 4.8) < 1e-9


def test_an_object_that_does_not_move_is_not_contradicted():
    """Where the object has not moved since an entity's first observation, static and object-fixed
    predict the same place: the frame cannot tell, the entity is confirmed as usual."""
    acc = Accumulator(PointType(), Points(np.zeros((0, 3)), np.zeros(0)), UpdateRule())
    T = _turning(0)
    for _ in range(3):
        stats = acc.update(Points(np.array([[0.0, 0.0, 0.5]]), np.ones(1)), invert(T))
    assert stats.contradicted == 0 and len(acc) == 1 and abs(acc.confidence[0] - 0.893) < 0.001  # two hits


def _segment_at(center, sigma_depth, sigma_direction_deg=1.0) -> Segments:
    return Segments("camera_left", np.array([center]), np.array([[0.0, 1.0, 0.0]]), np.array([0.015]),
                    np.array([0.9]), np.ones(1, np.int64),
                    {"sigma_depth_m": np.array([sigma_depth]), "sigma_direction_rad": np.radians([sigma_direction_deg])})


def test_association_of_an_uncertain_far_segment_and_a_precise_near_one():
    """A model segment observed again 5 mm deeper: at 0.8 m with a disparity sigma of 0.25 px the depth
    sigma is 0.8^2 / (600 * 0.08) * 0.25 = 3.3 mm, and the two observations (model and frame) are 2.5 *
    sqrt(2) * 3.3 = 11.8 mm apart at 2.5 sigmas, capped at 7.5 mm: they correspond, with a confirmation
    worth log(0.5 / 0.25) = 0.69 only (gate 2.5 times the paper's). At 0.3 m the same disparity sigma is
    0.5 mm: the gate stays the paper's 3 mm, and 5 mm deeper is another thing."""
    kind = LineSegmentType()
    for depth, sigma, expect in ((0.8, 0.8 ** 2 / 48 * 0.25, True), (0.3, 0.3 ** 2 / 48 * 0.25, False)):
        T = make_transform(np.eye(3), [0.0, 0.0, depth])       # object frame at the segment
        context = FrameContext(T, INTR)
        model = kind.observe(_segment_at([0.0, 0.0, depth], sigma).transformed(invert(T), "gripper"), context)
        deeper = kind.observe(_segment_at([0.0, 0.0, depth + 0.005], sigma).transformed(invert(T), "gripper"), context)
        i, j, cost, wide = kind.correspondences(model, deeper)
        assert (len(i) == 1) == expect
        if expect:
            assert abs(wide[0] - 2.5) < 1e-9 and abs(UpdateRule().confirmation(wide)[0] - np.log(2)) < 1e-9
    # merged, the far segment's own sigma falls by sqrt(2): its next gate is narrower
    T = make_transform(np.eye(3), [0.0, 0.0, 0.8])
    context = FrameContext(T, INTR)
    model = kind.observe(_segment_at([0.0, 0.0, 0.8], 0.0033).transformed(invert(T), "gripper"), context)
    again = kind.observe(_segment_at([0.0, 0.0, 0.8], 0.0033).transformed(invert(T), "gripper"), context)
    merged = kind.merge(model, again, np.array([0]), np.array([0]), context)
    assert abs(sigmas(merged)[0][0] - 0.0033 / np.sqrt(2)) < 1e-9


def _observed_from_two_aspects(kind: LineSegmentType, sigma_deg: float, turn_deg: float) -> list:
    """[(observation, T_camera_object)] of ``_one_segment`` claiming a direction sigma of ``sigma_deg``,
    seen from the front and from a camera turned ``turn_deg`` about the y axis."""
    observed = []
    for turn in (0.0, turn_deg):
        T = make_transform(Rotation.from_rotvec([0, np.radians(turn), 0]).as_matrix(), [0.0, 0.0, 0.5])
        segment = _one_segment()
        segment.extra["sigma_direction_rad"] = np.array([np.radians(sigma_deg)])
        observed.append((kind.observe(segment, FrameContext(T, INTR)), T))
    return observed


def test_a_confirmed_segment_whose_direction_is_unsure_is_not_accepted_until_another_aspect_pins_it():
    """A piece alone on its stretch near the epipolar direction carries a direction sigma of 15
    degrees: however often one view confirms it, the model does not accept it (confidence written
    under 0.5); a second view 40 degrees about the line pins its direction through the two planes,
    and it is accepted."""
    kind = LineSegmentType()
    limit = LineModelParams().max_direction_sigma_deg
    observed = _observed_from_two_aspects(kind, 15.0, 40.0)
    one_aspect = observed[0][0]
    for _ in range(3):
        one_aspect = kind.merge(one_aspect, observed[0][0], np.array([0]), np.array([0]),
                                FrameContext(observed[0][1], INTR))
    rules = LineModelParams(max_direction_sigma_deg=limit, single_aspect_sigma_deg=None)
    model = to_model(one_aspect, np.array([0.95]), np.array([4]), rules=rules)
    assert np.degrees(model.extra["sigma_direction_rad"][0]) > limit
    assert model.confidence[0] == UNSURE_CONFIDENCE and not model.accepted[0]
    assert model.extra["direction_held"][0]                      # confident, held back for its direction
    assert not to_model(one_aspect, np.array([0.3]), np.array([1]), rules=rules).extra["direction_held"][0]
    assert to_model(one_aspect, np.array([0.95]), np.array([4]), rules=None).accepted[0]
    assert not to_model(one_aspect, np.array([0.95]), np.array([4]), rules=None).extra["direction_held"][0]
    two_aspects = kind.merge(one_aspect, observed[1][0], np.array([0]), np.array([0]),
                             FrameContext(observed[1][1], INTR))
    model = to_model(two_aspects, np.array([0.95]), np.array([5]), rules=rules)
    assert np.degrees(model.extra["sigma_direction_rad"][0]) < limit
    assert model.confidence[0] == 0.95 and model.accepted[0] and not model.extra["direction_held"][0]


def test_a_segment_seen_from_one_aspect_must_be_surer_of_its_direction():
    """Confirmed four times from one aspect by pieces claiming 4 degrees, a segment claims 2 degrees
    (four observations' information), within the 5-degree limit but over the 1.5 degrees required
    of one aspect: it is held back. A second aspect 30 degrees about the line lifts the
    one-aspect limit, and it is accepted. The observations' own view planes stay out of the model."""
    params = LineModelParams()
    kind = LineSegmentType(params)
    observed = _observed_from_two_aspects(kind, 4.0, 30.0)
    assert "view_normal" in observed[0][0].extra
    one_aspect = kind.concatenate(kind.empty("gripper"), observed[0][0])
    assert not set(OBSERVATION_ONLY) & set(one_aspect.extra)
    for _ in range(3):
        one_aspect = kind.merge(one_aspect, observed[0][0], np.array([0]), np.array([0]),
                                FrameContext(observed[0][1], INTR))

    def written(model_segments, observations):
        return to_model(model_segments, np.array([0.95]), np.array([observations]), rules=params)

    model = written(one_aspect, 4)
    sigma_deg = np.degrees(model.extra["sigma_direction_rad"][0])
    assert params.single_aspect_sigma_deg < sigma_deg < params.max_direction_sigma_deg
    assert model.confidence[0] == UNSURE_CONFIDENCE and not model.accepted[0]
    two_aspects = kind.merge(one_aspect, observed[1][0], np.array([0]), np.array([0]),
                             FrameContext(observed[1][1], INTR))
    model = written(two_aspects, 5)
    assert np.degrees(model.extra["sigma_direction_rad"][0]) < params.max_direction_sigma_deg
    assert model.confidence[0] == 0.95 and model.accepted[0]


def test_views_within_the_aspect_span_count_as_one_aspect():
    """Three segments claiming a 2-degree direction sigma, seen from one view, from two views 12
    degrees apart and from two views 20 degrees apart: with a span of 15 degrees only the last is
    known (the first two are one aspect, held to 1.5 degrees); with a span of 0, one stored view is one aspect."""
    views = np.zeros((3, 6, 3), np.float32)
    views[:, 0] = [0, 0, 1]
    for row, degrees in ((1, 12.0), (2, 20.0)):
        views[row, 1] = [np.sin(np.radians(degrees)), 0, np.cos(np.radians(degrees))]
    segments = Segments("gripper", np.zeros((3, 3)), np.tile([1.0, 0, 0], (3, 1)), np.full(3, 0.02), np.ones(3),
                        np.full(3, 4), {"views": views, "inv_var_direction": np.full(3, np.radians(2.0) ** -2)})
    def rules(single_aspect_sigma_deg, span_deg):
        return LineModelParams(max_direction_sigma_deg=5.0, single_aspect_sigma_deg=single_aspect_sigma_deg,
                               single_aspect_span_deg=span_deg)

    assert direction_known(segments, rules(1.5, 15.0)).tolist() == [False, False, True]
    assert direction_known(segments, rules(1.5, 0.0)).tolist() == [False, True, True]
    assert direction_known(segments, rules(None, 15.0)).all()


def test_plane_agreement_holds_back_a_direction_whose_planes_do_not_meet_on_one_line():
    """Two segments along x, each set by three view planes (unit weights): the first's planes all
    contain x; the second's third plane misses x by 9 degrees, so its planes meet on no one line (the
    least eigenvalue of their information is 0.0123 of the middle one). With ``plane_agreement``
    0.006 only the first is known; with 0.02, or without the rule, both."""
    def planes(*normals):
        n = np.array(normals, float)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return (n[:, :, None] * n[:, None, :]).sum(axis=0)

    tilt = np.radians(9.0)
    dir_info = np.stack([planes([0, 0, 1], [0, 1, 0], [0, 1, 1]),
                         planes([0, 0, 1], [0, 1, 0], [np.sin(tilt), np.cos(tilt) / np.sqrt(2), np.cos(tilt) / np.sqrt(2)])])
    views = np.zeros((2, 6, 3), np.float32)
    views[:, 0], views[:, 1] = [0, 0, 1], [np.sin(np.radians(20.0)), 0, np.cos(np.radians(20.0))]
    segments = Segments("gripper", np.zeros((2, 3)), np.tile([1.0, 0, 0], (2, 1)), np.full(2, 0.02), np.ones(2),
                        np.full(2, 4), {"views": views, "inv_var_direction": np.full(2, np.radians(1.0) ** -2),
                                        "dir_info": dir_info})
    values = np.linalg.eigvalsh(dir_info)
    assert values[0, 0] < 1e-12 and 0.012 < values[1, 0] / values[1, 1] < 0.0125
    assert direction_known(segments, LineModelParams(plane_agreement=0.006)).tolist() == [True, False]
    assert direction_known(segments, LineModelParams(plane_agreement=0.02)).all()
    assert direction_known(segments, LineModelParams()).all()


def test_duplicates_merge_in_disjoint_pairs_and_keep_every_observation():
    """Three copies of one segment (pairs 0-1, 1-2, 0-2 all the same): merged in rounds of disjoint
    pairs, one survives with every observation and every view's information (with one_to_one, whose
    two sides were apart, a winner absorbed two losers and kept one's sums)."""
    kind = LineSegmentType()
    context = FrameContext(make_transform(np.eye(3), [0, 0, 0.5]), INTR)
    copies = Segments("object", np.array([[0, 0, 0], [0.0005, 0, 0], [0.001, 0, 0.0]]), np.tile([0, 1.0, 0], (3, 1)),
                      np.full(3, 0.01), np.ones(3), np.ones(3, np.int64))
    for log_odds in ([0.0, 1.0, 0.5], [1.0, 0.0, 0.5]):
        core = Accumulator(kind, kind.empty("object"))
        core.entities = kind.concatenate(kind.empty("object"), kind.observe(copies, context))
        core.log_odds, core.observations = np.array(log_odds), np.array([3, 5, 7])
        core.views, core.last_confirmed = np.array([4, 6, 8]), np.zeros(3, np.int64)
        core.static_sum = np.array([-3.0, 0.4, -1.0])
        i, j = _sharing(np.array([0, 1, 2]), np.array([0, 0, 0]))
        merged = core._consolidate(i, j)
        live = np.isfinite(core.log_odds)
        assert merged == 2 and live.sum() == 1
        assert core.observations[live].sum() == 15 and core.entities.extra["weight"][live].sum() == 3
        assert core.static_sum[live] == [0.4]     # the larger evidence of looking still


def test_disjoint_pairs_share_no_entity_on_either_side():
    a, b, cost = np.array([0, 1, 0, 3]), np.array([1, 2, 2, 4]), np.array([1.0, 0.5, 2.0, 1.0])
    chosen = disjoint_pairs(a, b, cost)
    ends = np.concatenate([a[chosen], b[chosen]])
    assert sorted(chosen) == [1, 3] and len(set(ends)) == len(ends)
    # one pair listed in both orders at one cost (as _sharing lists them): chosen once, not never
    assert list(disjoint_pairs(np.array([0, 1]), np.array([1, 0]), np.array([0.1, 0.1]))) == [0]


def _pieces(centers, directions, lengths):
    """Left-image pieces (``Segments2D``) with the given centres (N, 2) px, directions (N, 2) and lengths (N,) px."""
    from accumcli.lines2d import Segments2D

    n = len(centers)
    return Segments2D(np.asarray(centers, float), np.asarray(directions, float), np.asarray(lengths, float),
                      np.ones(n, np.int8), np.full(n, 30.0), np.arange(n), np.zeros(n), np.asarray(directions, float))


def test_planes_of_unmatched_pieces_from_another_aspect_pin_a_direction_stereo_tilted():
    """A segment along y seen from the front, its stereo direction tilted 6 degrees in depth (within the
    plane through the camera and the segment, which one view cannot check): a left piece along the true
    edge in frames 20 and 22 degrees around it adds their planes, which cross the first one in the
    true direction, and the second frame's view makes a second aspect (``to_model``'s one-aspect rule);
    a piece 2 px beside the projection gives nothing."""
    rules = LineModelParams()
    kind = LineSegmentType(rules)
    front = make_transform(np.eye(3), [0.0, 0.0, 0.5])
    tilted = Rotation.from_rotvec([np.radians(6.0), 0.0, 0.0]).apply([0.0, 1.0, 0.0])   # towards the camera
    model = kind.observe(_copy(_one_segment(tuple(tilted))), FrameContext(front, INTR))
    model.confidence = np.array([0.9])

    def off_y(segments):
        return np.degrees(np.arccos(abs(segments.directions[0, 1])))

    assert abs(off_y(model) - 6.0) < 0.1 and not direction_known(model, rules)[0]
    half = 600.0 * 0.006 / 0.5   # the 12 mm edge along y at 0.5 m: 14.4 px, through the image centre
    beside = _pieces([[INTR.cx + 2.0, INTR.cy]], [[0.0, 1.0]], [2 * half - 1])   # the gate: 1.5 px
    side = make_transform(Rotation.from_rotvec([0.0, np.radians(20.0), 0.0]).as_matrix(), [0.0, 0.0, 0.5])
    assert len(planes_from_image(model, np.array([True]), beside, FrameContext(side, INTR), rules)) == 0
    assert abs(off_y(model) - 6.0) < 0.1 and model.extra["image_planes"][0] == 0
    on_edge = _pieces([[INTR.cx, INTR.cy]], [[0.0, 1.0]], [2 * half - 1])
    for turn, frames in ((20.0, 1), (22.0, 2)):
        side = make_transform(Rotation.from_rotvec([0.0, np.radians(turn), 0.0]).as_matrix(), [0.0, 0.0, 0.5])
        assert planes_from_image(model, np.array([True]), on_edge, FrameContext(side, INTR), rules).tolist() == [0]
        assert model.extra["image_planes"][0] == frames
        assert int(model.extra["views"][0].any(axis=1).sum()) == frames   # the first plane's view waits
    assert off_y(model) < 1.5          # the planes cross in the edge; stereo (6 deg sigma) pulls a little
    assert direction_known(model, rules)[0]


def _twin_core(kind: LineSegmentType, turns_deg, offsets_m, confidences, tilt_deg=12.0, sigma_deg=15.0,
               lengths_m=(0.012, 0.012)) -> Accumulator:
    """An accumulator of segments along y, one per camera turned ``turns_deg`` about y, each at
    ``offsets_m`` along x and triangulated ``tilt_deg`` tilted towards its camera (within its view plane,
    stereo's weak direction), claiming a direction sigma of ``sigma_deg``, at ``confidences``, ``lengths_m`` long."""
    core = Accumulator(kind, kind.empty("gripper"))
    core.entities = kind.empty("gripper")
    for turn, offset, length in zip(turns_deg, offsets_m, lengths_m):
        T, tilted = _tilted_towards_camera(turn, tilt_deg)
        segment = _one_segment(tuple(tilted))
        segment.centers, segment.lengths = np.array([[offset, 0.0, 0.0]]), np.array([length])
        segment.extra["sigma_direction_rad"] = np.array([np.radians(sigma_deg)])
        core.entities = kind.concatenate(core.entities, kind.observe(segment, FrameContext(T, INTR)))
    n = len(turns_deg)
    core.log_odds = np.array([logit(c) for c in confidences])
    core.observations, core.views = np.full(n, 3, np.int64), np.full(n, 3, np.int64)
    core.last_confirmed, core.static_sum = np.zeros(n, np.int64), np.zeros(n)
    return core


def _angle_to_y_deg(segments: Segments) -> np.ndarray:
    return np.degrees(np.arccos(np.abs(segments.directions[:, 1])))


def test_twins_of_one_edge_from_two_aspects_are_merged_as_the_model_is_written():
    """Two segments of one edge, 2 mm apart, each triangulated 12 degrees tilted towards its own camera
    (40 degrees apart about the edge) and unsure of it (15 degrees): neither is accepted alone, and they
    are too far apart in direction (8 degrees) and position for the paper's metric to call them one.
    Their view planes together pin the edge: ``merged_twins`` makes them one segment within 2 degrees of
    it, which is accepted at the more confident one's confidence; the running accumulator is untouched."""
    params = LineModelParams()
    kind = LineSegmentType(params)
    core = _twin_core(kind, (0.0, 40.0), (0.0, 0.002), (0.6, 0.3))
    assert (_angle_to_y_deg(core.entities) > 11.0).all()
    alone = to_model(core.entities, core.confidence, core.observations, rules=params)
    assert not alone.accepted.any() and alone.extra["direction_held"][0]
    same, _ = kind.same(core.entities, np.array([0]), np.array([1]))
    assert not same[0]
    centers = core.entities.centers.copy()
    merged = merged_twins(core, params)
    assert len(merged) == 1 and len(core) == 2 and np.array_equal(core.entities.centers, centers)
    assert merged.observations[0] == 6 and np.isclose(merged.confidence[0], 0.6)
    model = to_model(merged.entities, merged.confidence, merged.observations, rules=params)
    assert model.accepted[0] and _angle_to_y_deg(model)[0] < 2.0


def test_what_is_not_a_twin_stays_apart():
    """Not merged: two segments seen from one aspect (their planes coincide: the direction would rest
    on their stereo directions, sure or not), two parallel edges 8 mm apart, one more than 3 times the
    other's length (``merge`` would trim it), and two segments that are both already accepted with a
    known direction (they cover their edge already)."""
    params = LineModelParams()
    kind = LineSegmentType(params)
    assert len(merged_twins(_twin_core(kind, (0.0, 2.0), (0.0, 0.002), (0.6, 0.3)), params)) == 2
    one_aspect = _twin_core(kind, (0.0, 2.0), (0.0, 0.002), (0.4, 0.3), tilt_deg=0.5, sigma_deg=1.0)
    assert len(merged_twins(one_aspect, params)) == 2           # their stereo directions alone would pin it
    assert len(merged_twins(one_aspect, LineModelParams(twin_min_view_deg=0.0))) == 1
    assert len(merged_twins(_twin_core(kind, (0.0, 40.0), (0.0, 0.008), (0.6, 0.3)), params)) == 2
    lengths = (0.040, 0.012)       # merged, the 40 mm one would be trimmed to 3 times the 12 mm one
    assert len(merged_twins(_twin_core(kind, (0.0, 40.0), (0.0, 0.002), (0.6, 0.3), lengths_m=lengths), params)) == 2
    assert len(merged_twins(_twin_core(kind, (0.0, 40.0), (0.0, 0.002), (0.6, 0.3), lengths_m=(0.030, 0.012)),
                            params)) == 1
    sure = _twin_core(kind, (0.0, 40.0), (0.0, 0.002), (0.9, 0.9), tilt_deg=0.5, sigma_deg=0.5)
    assert direction_known(sure.entities, params).all()
    assert len(merged_twins(sure, params)) == 2
    assert len(merged_twins(_twin_core(kind, (0.0, 40.0), (0.0, 0.002), (0.9, 0.9), tilt_deg=0.5, sigma_deg=15.0),
                            params)) == 1                       # unsure of their direction: merged


def test_the_written_model_merges_twins_unless_told_not_to():
    """``LineAccumulation.model()`` writes the twins merged; with ``merge_twins`` off, as accumulated."""
    from accumcli.pipeline import AccumulateParams, LineAccumulation

    for merge, expected in ((True, 1), (False, 2)):
        acc = LineAccumulation(AccumulateParams(line_model=LineModelParams(merge_twins=merge)))
        acc.core = _twin_core(acc.entity_type, (0.0, 40.0), (0.0, 0.002), (0.6, 0.3))
        assert len(acc.model()) == expected and len(acc.core) == 2


def _step_images(u_left: float, z: float) -> tuple[Gradients, Gradients]:
    """Gradients of a stereo pair showing one vertical step edge at ``u_left`` px (area-sampled, so its
    place is sub-pixel) at depth ``z`` m (the right image's edge at its disparity)."""
    columns = np.arange(640, dtype=float)

    def image(u):
        return np.repeat((60 + 120 * np.clip(columns + 0.5 - u, 0, 1))[None, :], 480, axis=0).astype(np.uint8)

    return Gradients.of(image(u_left)), Gradients.of(image(u_left - INTR.fx * INTR.baseline / z))


def _turned(deg: float, shift) -> np.ndarray:
    """T_camera_object: the object 0.5 m in front, turned by ``deg`` about its y axis, moved by ``shift`` m."""
    return make_transform(Rotation.from_rotvec([0.0, np.radians(deg), 0.0]).as_matrix(), np.add([0.0, 0.0, 0.5], shift))


def test_images_confirm_a_segment_where_it_moved_only_if_right_in_3d_and_seen_from_a_new_aspect():
    """An edge along y through the object's origin, first seen at T0; in a frame turned by 12 degrees
    about y and moved 10 mm across (x) both images show it where it moved. A segment on it is
    confirmed; one tilted 15 degrees in depth within the first view's plane (which that view could
    not tell apart) projects off the edge from the new aspect and is not; nor is either where the
    right image shows the edge at another depth, nor from the first aspect, nor where the object
    moved too little across the line (1 mm, 1.2 px) or along it only (a static line would look the
    same), nor a segment that is not a candidate."""
    kind = LineSegmentType()
    T0 = _turned(0.0, [0.0, 0.0, 0.0])
    tilt = np.radians(15.0)
    first = Segments("gripper", np.zeros((2, 3)), np.array([[0.0, 1.0, 0.0], [0.0, np.cos(tilt), np.sin(tilt)]]),
                     np.array([0.04, 0.04]), np.array([0.9, 0.9]), np.ones(2, np.int64),
                     {"sigma_depth_m": np.array([0.001, 0.001])})
    model = kind.observe(first, FrameContext(T0, INTR))
    sensed = first.transformed(T0, "camera_left")        # the first observation, held still in the camera

    def confirmed(T, u_edge, depth=0.5, candidates=(True, True)):
        left, right = _step_images(u_edge, depth)
        still = sensed.transformed(invert(T), "gripper")
        return kind.image_confirmed(model, still, FrameContext(T, INTR, left_gradients=left, right_gradients=right),
                                    np.array(candidates)).tolist()

    def u_at(x):    # where the edge, moved x m across, projects in the left image
        return INTR.fx * x / 0.5 + INTR.cx

    T1 = _turned(12.0, [0.01, 0.0, 0.0])
    assert confirmed(T1, u_at(0.01)) == [True, False]
    assert confirmed(T1, u_at(0.01), candidates=(False, True)) == [False, False]
    assert confirmed(T1, u_at(0.01), depth=0.48) == [False, False]      # the right image's edge 2 px off
    assert confirmed(_turned(0.0, [0.01, 0.0, 0.0]), u_at(0.01)) == [False, False]       # the first aspect
    assert confirmed(_turned(12.0, [0.001, 0.0, 0.0]), u_at(0.001)) == [False, False]    # 1.2 px across
    assert confirmed(_turned(12.0, [0.0, 0.01, 0.0]), INTR.cx) == [False, False]         # moved along it


def test_an_image_confirmation_replaces_a_miss_only_when_switched_on():
    """A segment seen in three frames of one aspect, then not extracted in a frame whose images show
    it where it moved, from a new aspect: the default misses it (its log-odds fall), with
    ``image_confirmation`` it gains that much instead and counts as confirmed that frame."""
    poses = [_turned(0.0, [0.0, 0.0, 0.0]), _turned(2.0, [0.0, 0.0, 0.0]), _turned(4.0, [0.0, 0.0, 0.0])]
    T1 = _turned(16.0, [0.01, 0.0, 0.0])
    left, right = _step_images(INTR.fx * 0.01 / 0.5 + INTR.cx, 0.5)
    edge = Segments("gripper", np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.array([0.04]), np.array([0.9]),
                    np.ones(1, np.int64), {"sigma_depth_m": np.array([0.001])})
    changes = {}
    for rule in (UpdateRule(), UpdateRule(image_confirmation=0.6)):
        kind = LineSegmentType()
        core = Accumulator(kind, kind.empty("camera_left"), rule)
        for T in poses:
            core.update(edge.transformed(T, "camera_left"), invert(T), FrameContext(T, INTR))
        before = float(core.log_odds[0])
        stats = core.update(Segments.empty("camera_left"), invert(T1),
                            FrameContext(T1, INTR, left_gradients=left, right_gradients=right))
        changes[rule.image_confirmation] = (float(core.log_odds[0]) - before, stats.missed, stats.image_confirmed,
                                            int(core.last_confirmed[0]) == core.frame - 1)
    assert changes[None][0] < -0.3 and changes[None][1:] == (1, 0, False)
    assert abs(changes[0.6][0] - 0.6) < 1e-12 and changes[0.6][1:] == (0, 1, True)
