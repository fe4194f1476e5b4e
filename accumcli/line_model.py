"""Local 3D line segments as an entity type of the accumulation core.

Entities are ``Segments`` in the object frame with running sums in ``extra``:

- position in information form: ``info`` (N, 3, 3), 1/m^2, and ``info_vec``
  (N, 3); the centre is ``info^-1 info_vec``. One observation's covariance is
  ``sigma_lat^2 I + (sigma_depth^2 - sigma_lat^2) r r^T`` (r the viewing ray:
  depth is the weak direction of stereo; with a pose's covariance,
  ``FrameContext.pose_covariance``, both sigmas, the direction's and the view
  plane's take on that pose's error at the observation: ``pose_sigmas``), and it informs the position only
  across its direction u: along the line, where a local segment is cut is
  arbitrary (the aperture problem), so observations are not averaged along
  the line (``anchor``, the information ``12 / length^2`` of the segment's
  first observation, only keeps the system solvable). Across the line the
  merge is thus a weighted average that trusts each view where it is precise,
  each view weighted by its match confidence;
- ``dir_info`` (N, 3, 3) sets the direction (``view_planes``, the default), in
  information form: the direction is the unit vector it weighs least (its
  smallest eigenvector). Each observation adds, weighted by its confidence,
  ``(I - u u^T) / sigma_u^2`` (towards its own direction u, as sure as the
  stereo fit made it) and ``n n^T / sigma_n^2``, which keeps the direction in
  the plane through the camera and the segment (normal n = ray x u). That
  plane is known as well as the left image's line: whatever tilt stereo's
  short baseline leaves (depth along the segment), the triangulated segment
  lies in it, so its only uncertainty is the line's own direction
  (``line_sigma_px`` of edge-point scatter over the segment's length in
  pixels) and the pose's rotation (``pose_rotation_sigma_deg``). One view
  gives back its own u; two views of a turning object give two distinct
  planes whose intersection is the direction, as sure as a wide-baseline
  triangulation. Why: near the critical plane a 2D line's angle error of 1
  degree (crowded edges bias it) tilts the stereo direction by 20 degrees
  along the viewing ray, and averaging keeps such errors;
- ``dir_sum`` (N, 3): the sum of the sign-aligned directions, each weighted
  by its confidence and the inverse variance of its direction, which sets the
  direction instead with ``accum accumulate --average-directions``. The
  planes trust the poses to ``pose_rotation_sigma_deg`` (or a pose's own rotation
  sigma where ``FrameContext.pose_covariance`` gives a larger one): ``--motion tracked``
  builds its intermediate models by averaging
  (``runs.accumulation.tracked_poses``); ``weight`` (N,): the sum of
  confidences;
- along the line, the segment covers the union of its extent and the merged
  observation's, its centre re-placed at the middle of that union: an
  observation of the same length shifted by 4 mm along the line moves the
  centre by 2 mm and lengthens the segment by 4 mm. The union is trimmed
  equally at both ends to at most ``max_extent`` observation lengths, so the
  centre stays at its middle. A confirmation by a piece cut further along the
  edge thus extends the segment instead of leaving a gap that neither
  neighbour covers (the metric forgives shifts of half a length, so the gap's
  own pieces confirm the neighbours and are never added). ``max_extent`` 3
  against 2: completeness higher on 14 of the suite's 19 rows and lower on
  none (median 0.568 -> 0.579), precision within 0.004 on every row;
- ``inv_var_position`` (N,), 1/m^2, and ``inv_var_direction`` (N,), 1/rad^2: sums of the
  inverse variances of the merged observations' depth (``sigma_depth_m``, the weak
  direction of stereo, so an upper bound of the position error) and direction
  (``sigma_direction_rad``), the latter (with ``view_planes``) raised to what
  ``dir_info`` holds in its weakest direction once distinct views pin it.
  Their inverse square roots are the segment's own sigmas that gate
  association (``metric.candidate_pairs``): an unsure far segment is looked
  for in a wider gate than a precise near one;
- ``views`` (N, K, 3): up to K unit directions (object frame, segment to
  camera) from which the segment was confirmed, at least ``view_step_deg``
  apart (zero vectors where unused): the set of aspects in which it has been
  seen.

Running sums are scaled down once their weight passes ``max_weight``, so a
long-lived segment still follows new evidence.

``expected`` (beyond the paper): a model segment should be seen in a frame only
if both its endpoints are in view (``visibility.segments_in_both_images``: in
front of the camera, ``IMAGE_MARGIN_PX`` inside both images and clear of the black wedges that
rectification of raw images leaves, where nothing can be seen), it
is not near the critical plane, and the camera looks at it from within
``aspect_margin_deg`` of a direction it was confirmed from. For a rigid object and
gripper, what is visible depends on the viewing direction only, so a segment
that turned away or behind the object is not punished. Nor is one whose edge the frame's left
image shows where it projects (``edge_evidence``: the median gradient across its projection at
least the extraction's Canny high threshold) while no left piece that became a 3D segment lies
along it (``unextracted_no_miss``, ``_unextracted``): there the extraction failed, not the object
(short, crowded and unmatched edges are turned into 3D in a tenth of the frames that show them),
and a miss would say the segment is not there when the image says it is. A frame whose image is
flat there, or that extracted a piece along it whose 3D segment went to another model segment (a
twin tilted in depth or set off along the viewing ray, which projects onto the same edge), misses
it as before. ``make suite`` (4 runs a row) against every expected frame missing: completeness
mean 0.667 -> 0.691, worst 0.306 -> 0.359 (dev_cube_small), dev_wedge_far 0.446 -> 0.539, the real
teabox 0.615 -> 0.650, median 0.673 both (dev_clutter, unchanged, is the median row); precision
median 0.975 -> 0.963, rows under 0.95 the same three (sim_105 0.944 -> 0.930, dev_cube_small
0.893 -> 0.908, the teabox's surface precision 0.541 -> 0.543), background the same. Without the
condition on extracted pieces (every frame showing the edge silent): completeness median 0.715,
mean 0.700, but precision median 0.958 and 7 rows under 0.95: the twins then lived on.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial import cKDTree

from .dominant_directions import DominantParams, covered, dominant_directions, observations_directed
from .edge_evidence import edge_evidence
from .edge_search import edge_candidates
from .geometry import check_points, check_transform, invert, outer, skew, transform_points, unit_or_zero
from .grouping import best_per_key
from .lines2d import Gradients, Segments2D, pieces_along
from .metric import MetricThresholds, candidate_pairs, d_o, d_p, pair_costs
from .recording import StereoIntrinsics
from .segments import Segments, concatenate
from .stereo import StereoParams, view_plane_normals
from .visibility import in_both_images



# an observation's own columns, not carried into the model (``LineSegmentType.concatenate``)
OBSERVATION_ONLY = ("view_normal", "view_sigma")
# the entity's sums that an observation adds to, scaled down together at ``max_weight`` (``dir_info``: view planes)
RUNNING_SUMS = ("info", "info_vec", "dir_sum", "weight", "inv_var_position", "inv_var_direction", "dir_info")
# ``image_confirmed``'s search (the tracker's: ``edge_search``): points along a segment, px searched across it
# each way, the shortest projection judged, and what counts as its edge there (grey levels per pixel across it, and the share of the gradient
# that lies across it)
IMAGE_SAMPLES = 9
IMAGE_SEARCH_PX = 3
IMAGE_MIN_LENGTH_PX = 5.0     # a shorter projection (a segment along its viewing ray) says little
IMAGE_MIN_GRADIENT = 4.0
IMAGE_MIN_COS = 0.85


@dataclass(frozen=True)
class LineModelParams:
    thresholds: MetricThresholds = MetricThresholds()
    lateral_sigma_px: float = StereoParams.lateral_sigma_px   # px, of observations without sigma_lateral_px
    max_weight: float = 20.0
    aspect_margin_deg: float = 15.0
    critical_angle_deg: float = 8.0   # AccumulateParams sets it to StereoParams.critical_angle_deg
    duplicate_shift: float = 0.25     # fraction of a length; closer centres along the line are duplicates
    max_views: int = 6                # viewing directions kept per segment
    view_step_deg: float = 10.0       # a new viewing direction is kept if this far from the stored ones
    max_extent: float = 3.0           # a model segment covers at most this many observation lengths
    reference_direction_sigma_deg: float = 2.0  # a direction this certain weighs as much as its confidence
    view_planes: bool = True          # directions from the planes of all views (``dir_info``; module docstring)
    line_sigma_px: float = 0.15       # scatter of a 2D line's edge points across it (dir_info's planes)
    pose_rotation_sigma_deg: float = 0.5  # rotation error of a pose, between the views whose planes meet
    min_plane_sine: float = 0.2       # a segment this near its viewing ray (sin) spans no plane worth using
    max_direction_sigma_deg: float | None = 5.0   # accepted only if its direction is this sure (``to_model``) ...
    single_aspect_sigma_deg: float | None = 1.5   # ... and this sure while confirmed from one aspect only,
    single_aspect_span_deg: float = 15.0          # i.e. from viewing directions all within this of each other
    unextracted_no_miss: bool = True  # a frame showing a segment's edge but extracting nothing along it does not miss it
    image_planes: bool = True         # unsure directions also take the view planes of unmatched left pieces
    image_plane_gate_px: float = 1.5  # ... lying along their projection: this near across it ...
    image_plane_gate_deg: float = 3.0  # ... and this near its angle (``planes_from_image``)
    image_plane_weight: float = 0.5   # such a plane weighs as a 3D observation of this confidence
    image_plane_min_frames: int = 2   # its view counts as an aspect once this many frames gave such planes
    plane_agreement: float | None = None  # accepted only if its planes agree this well (``direction_known``; None: off)
    merge_twins: bool = True          # the written model merges twins from different aspects (``merged_twins``) ...
    twin_across_m: float = 0.004      # ... overlapping, this near across each other's line ...
    twin_max_angle_deg: float = 20.0  # ... and this near in direction ...
    twin_plane_agreement: float = 0.01  # ... whose planes together meet on one line (``direction_known``'s ratio) ...
    twin_min_view_deg: float = 5.0    # ... seen together from views spanning at least this
    dominant: DominantParams | None = DominantParams()  # held directions from the model's shared ones (None: off)
    image_tolerance_px: float = 0.4   # ``image_confirmed``: the edge found this near the projection ...
    image_share: float = 0.7          # ... at this share of the points along the segment, in both images ...
    image_shift_px: float = 2.0       # ... where its still place projects this far across it


@dataclass
class FrameContext:
    """What the entity type needs to know of the frame: the pose used, T_camera_object (4, 4)
    (checked: ``InputError`` if not a rigid transform), the cameras, the frame's
    ``border_distance`` (``StereoFrame``: where rectification left no image; None: none), for
    ``expected``'s test of what the extraction missed, the left image's gradients and the left pieces
    that became 3D segments (None: no such test), the model's shared directions (``observe``) and the
    pose's covariance, which its observations take on (``pose_sigmas``)."""

    T_camera_object: np.ndarray
    intrinsics: StereoIntrinsics
    border_distance: tuple[np.ndarray, np.ndarray] | None = None
    left_gradients: Gradients | None = None   # the left image's (``expected``: does it show a segment's edge?)
    extracted_left: Segments2D | None = None  # the left pieces that gave this frame's 3D segments
    shared: Segments | None = None    # the model's accepted segments seen from more than one aspect (``shared_directions``)
    pose_covariance: np.ndarray | None = None   # (6, 6) of the pose (``motion.fuse``); None: exact (``pose_sigmas``)
    right_gradients: Gradients | None = None  # the right image's (``image_confirmed``; None: no such test)

    def __post_init__(self):
        self.T_camera_object = check_transform(self.T_camera_object, "T_camera_object")


class LineSegmentType:
    """The accumulation core's entity type for ``Segments`` (see the module docstring)."""

    def __init__(self, params: LineModelParams = LineModelParams()):
        self.params = params

    def empty(self, frame_id: str) -> Segments:
        s = Segments.empty(frame_id)
        s.extra = {"info": np.zeros((0, 3, 3)), "info_vec": np.zeros((0, 3)), "anchor": np.zeros(0),
                   "dir_sum": np.zeros((0, 3)), "weight": np.zeros(0),
                   "inv_var_position": np.zeros(0), "inv_var_direction": np.zeros(0),
                   "views": np.zeros((0, self.params.max_views, 3), np.float32), "image_planes": np.zeros(0)}
        if self.params.view_planes:
            s.extra["dir_info"] = np.zeros((0, 3, 3))
        return s

    def size(self, entities: Segments) -> int:
        return len(entities)

    def select(self, entities: Segments, index) -> Segments:
        return entities.select(index)

    def concatenate(self, first: Segments, second: Segments) -> Segments:
        """The two together, without an observation's own view plane (``OBSERVATION_ONLY``): a model
        segment is not one view."""
        parts = [replace(x, extra={k: v for k, v in x.extra.items() if k not in OBSERVATION_ONLY})
                 for x in (first, second)]
        return concatenate(parts, first.frame_id)

    def transform(self, entities: Segments, T_new_old: np.ndarray) -> Segments:
        return entities.transformed(T_new_old, entities.frame_id)

    def correspondences(self, model: Segments, observed: Segments):
        """Pairs within the metric's thresholds, gated by both sides' own sigmas where they carry them
        (model segments and extracted ones alike; see ``sigmas``) and, for an observation made ready
        by ``observe``, by the direction gate by covariance (``metric``: its view plane against the
        model segment's direction information ``dir_info``), with each pair's widening."""
        x = observed.extra
        plane = (x["view_normal"], x["view_sigma"]) if "view_normal" in x else None
        information = None
        if plane is not None and "dir_info" in model.extra:    # in 1/rad^2 (``observe``'s reference)
            information = model.extra["dir_info"] / np.radians(self.params.reference_direction_sigma_deg) ** 2
        return candidate_pairs(model.centers, model.directions, model.lengths, observed.centers,
                               observed.directions, observed.lengths, self.params.thresholds,
                               sigmas_a=sigmas(model), sigmas_b=sigmas(observed), widening=True, plane_b=plane,
                               info_a=information)

    def pair_cost(self, a: Segments, b: Segments) -> np.ndarray:
        ok, cost, _ = pair_costs(a.centers, a.directions, a.lengths, b.centers, b.directions, b.lengths,
                                 self.params.thresholds, sigmas(a), sigmas(b))
        return cost

    def essentials(self, entities: Segments) -> Segments:
        """Centres, directions, lengths and the two sigmas (``sigmas``) only."""
        sig = sigmas(entities)
        extra = {} if sig is None else {"sigma_depth_m": sig[0], "sigma_direction_rad": sig[1]}
        return Segments(entities.frame_id, entities.centers, entities.directions, entities.lengths,
                        entities.confidence, entities.observations, extra)

    def same(self, model: Segments, i: np.ndarray, j: np.ndarray):
        """Pairs of model segments within the metric's thresholds whose centres are also within
        ``duplicate_shift`` of a length along their line: the same piece twice, not two
        neighbouring pieces (which the paper's metric, made for noisy observations, would pair)."""
        th = self.params.thresholds
        angle = d_o(model.directions[i], model.directions[j])
        position = d_p(model.centers[i], model.directions[i], model.lengths[i], model.centers[j],
                       model.directions[j], model.lengths[j], th.s_p)
        along = np.abs(np.sum((model.centers[j] - model.centers[i]) * model.directions[i], axis=1))
        same = (angle <= np.radians(th.s_o_deg)) & (position <= th.s_p) & (
            along <= self.params.duplicate_shift * np.minimum(model.lengths[i], model.lengths[j]))
        return same, (position / th.s_p) ** 2 + (angle / np.radians(th.s_o_deg)) ** 2

    def observe(self, observed: Segments, context: FrameContext) -> Segments:
        """Initialise the running sums of observations (already in the object frame; ``InputError``
        if a centre is not finite); unsure ones first take the direction the model shares where their
        view plane holds it (``context.shared``, ``dominant_directions.observations_directed``)."""
        check_points(observed.centers, "observed segment centres")
        p = self.params
        camera_in_object = invert(context.T_camera_object)[:3, 3]
        to_camera = camera_in_object - observed.centers
        distance = np.linalg.norm(to_camera, axis=1, keepdims=True)
        ray = to_camera / np.maximum(distance, 1e-9)
        if p.dominant is not None and p.dominant.observations and context.shared is not None and \
                "sigma_direction_rad" in observed.extra:
            observed = observations_directed(observed, ray, context.shared, p.dominant)
        depth = distance[:, 0]
        sigma_lat = depth * observed.extra.get("sigma_lateral_px", p.lateral_sigma_px) / context.intrinsics.fx
        sigma_depth = observed.extra.get("sigma_depth_m", sigma_lat * 10)
        sigma_direction = observed.extra.get("sigma_direction_rad", np.full(len(observed), np.radians(5.0)))
        if context.pose_covariance is not None:     # the pose's own error, on top of the images'
            pose_position, rotation = pose_sigmas(observed.centers, context.pose_covariance)
            sigma_lat, sigma_depth = np.hypot(sigma_lat, pose_position), np.hypot(sigma_depth, pose_position)
            sigma_direction = np.hypot(sigma_direction, rotation)
        u = observed.directions
        # covariance a I + b r r^T; its inverse by Sherman-Morrison: (I - b / (a + b) r r^T) / a
        a = sigma_lat ** 2
        b = np.maximum(sigma_depth, sigma_lat) ** 2 - a
        w = np.clip(observed.confidence, 0.05, 1.0)
        # restricted to the plane across u: P = I - u u^T, P cov^-1 P = (P - b / (a + b) (P r)(P r)^T) / a
        across = np.eye(3) - u[:, :, None] * u[:, None, :]
        ray_across = ray - np.sum(ray * u, axis=1, keepdims=True) * u
        info = (across - (b / (a + b))[:, None, None] * ray_across[:, :, None] * ray_across[:, None, :]) * \
            (w / a)[:, None, None]
        anchor = w / (observed.lengths ** 2 / 12)
        info = info + anchor[:, None, None] * u[:, :, None] * u[:, None, :]
        out = Segments(observed.frame_id, observed.centers, u, observed.lengths, observed.confidence,
                       observed.observations)
        sigma_position = np.maximum(sigma_depth, sigma_lat)
        reference = np.radians(p.reference_direction_sigma_deg)
        direction_weight = w * (reference / np.maximum(sigma_direction, 1e-3)) ** 2
        out.extra = {"info": info, "info_vec": np.einsum("nij,nj->ni", info, observed.centers), "anchor": anchor,
                     "dir_sum": u * direction_weight[:, None], "weight": w,
                     "inv_var_position": 1.0 / np.maximum(sigma_position, 1e-5) ** 2,
                     "inv_var_direction": 1.0 / np.maximum(sigma_direction, 1e-4) ** 2,
                     "views": _new_views(ray, self.params.max_views), "image_planes": np.zeros(len(observed))}
        if p.view_planes:
            normal = np.cross(ray, u)      # of the plane through the camera and the segment (module docstring)
            sine = np.linalg.norm(normal, axis=1)
            normal = normal / np.maximum(sine, 1e-9)[:, None]
            length_px = context.intrinsics.fx * observed.lengths * sine / np.maximum(depth, 1e-9)
            sigma_plane = _plane_sigma(length_px, p, context)
            plane_weight = np.where(sine >= p.min_plane_sine, w * (reference / sigma_plane) ** 2, 0.0)
            out.extra["dir_info"] = direction_weight[:, None, None] * across + \
                plane_weight[:, None, None] * outer(normal)
            # the observation's own view plane, for the direction gate by covariance (``correspondences``)
            out.extra["view_normal"] = np.where((sine >= p.min_plane_sine)[:, None], normal, 0.0)
            out.extra["view_sigma"] = sigma_plane
        return out

    def merge(self, model: Segments, observed: Segments, mi: np.ndarray, oi: np.ndarray,
              context: FrameContext) -> Segments:
        """Information-weighted merge of the matched pairs (model index ``mi``, observed ``oi``),
        in place (the model's arrays are updated and returned)."""
        x, o = model.extra, observed.extra
        extra = x  # updated in place: copying the whole model's state every frame would cost more than the merge
        scale = np.minimum(1.0, self.params.max_weight / np.maximum(x["weight"][mi], 1e-9))
        for key in (k for k in RUNNING_SUMS if k in x):
            shape = (-1,) + (1,) * (x[key].ndim - 1)
            extra[key][mi] = x[key][mi] * scale.reshape(shape)
        sign = np.where(np.sum(model.directions[mi] * observed.directions[oi], axis=1) >= 0, 1.0, -1.0)
        # the observation informs the position across its direction only (where a local segment was
        # cut along the line is arbitrary); the place along the line is set by the extents below
        u_o = observed.directions[oi]
        along = o["anchor"][oi][:, None, None] * u_o[:, :, None] * u_o[:, None, :]
        extra["info"][mi] += o["info"][oi] - along
        extra["info_vec"][mi] += o["info_vec"][oi] - np.einsum("nij,nj->ni", along, observed.centers[oi])
        extra["dir_sum"][mi] += o["dir_sum"][oi] * sign[:, None]
        extra["weight"][mi] += o["weight"][oi]
        extra["inv_var_position"][mi] += o["inv_var_position"][oi]
        extra["inv_var_direction"][mi] += o["inv_var_direction"][oi]
        views = x["views"][mi]
        for k in range(o["views"].shape[1]):
            new = o["views"][oi, k]
            if not new.any():
                break  # an observation has one view; a merged model segment a few
            views = _add_view(views, new, np.radians(self.params.view_step_deg))
        extra["views"][mi] = views
        centers = model.centers
        solved = np.linalg.solve(extra["info"][mi], extra["info_vec"][mi][:, :, None])[:, :, 0]
        directions = model.directions
        if "dir_info" in x:
            extra["dir_info"][mi] += o["dir_info"][oi]    # u u^T and n n^T: the sign of u does not matter
            u = _direction_of_planes(extra, model.directions, mi, self.params)
        else:
            u = unit_or_zero(extra["dir_sum"][mi])
        directions[mi] = u
        # extent along the line: the union of the model's and the observation's, at most max_extent lengths
        rel = observed.centers[oi] - model.centers[mi]
        half_obs = observed.lengths[oi] / 2 * np.abs(np.sum(observed.directions[oi] * u, axis=1))
        lo = np.minimum(-model.lengths[mi] / 2, np.sum(rel * u, axis=1) - half_obs)
        hi = np.maximum(model.lengths[mi] / 2, np.sum(rel * u, axis=1) + half_obs)
        limit = self.params.max_extent * observed.lengths[oi]
        excess = np.maximum(hi - lo - limit, 0.0) / 2
        lo, hi = lo + excess, hi - excess
        along = np.sum((solved - model.centers[mi]) * u, axis=1)
        centers[mi] = solved + ((lo + hi) / 2 - along)[:, None] * u
        extra["info_vec"][mi] = np.einsum("nij,nj->ni", extra["info"][mi], centers[mi])
        lengths = model.lengths
        lengths[mi] = hi - lo
        return Segments(model.frame_id, centers, directions, lengths, model.confidence, model.observations, extra)

    def image_confirmed(self, model: Segments, still: Segments, context: FrameContext,
                        candidates: np.ndarray) -> np.ndarray:
        """(N,) bool: of the ``candidates`` (N,) bool, the model segments (object frame) whose edge both
        images show where this frame's pose projects them, from a new aspect (``accumulate``, step 4): at
        ``IMAGE_SAMPLES`` points along the middle 80 % of the segment, the strongest gradient across its
        projection within ``IMAGE_SEARCH_PX`` (the tracker's ``edge_search``) lies within
        ``image_tolerance_px`` of it at ``image_share`` of them, in the left and in the right image (each
        searched across its own projected line). Judged only where the segment is in view
        (``in_both_images``), projects at least ``IMAGE_MIN_LENGTH_PX`` long in both images and as far
        from the rows as ``expected`` asks (near them the right image repeats the left one's line), and
        where (1) its first observation held still in the sensor's frame (``still`` (N,), object frame)
        projects ``image_shift_px`` or more across it in the left image (a static edge would show as
        well, and along its own line a static line shows the same), and (2) the frame sees it from more
        than ``view_step_deg`` from every stored view (from one aspect the images repeat the plane that
        one stereo pair saw, whatever the segment's tilt in depth: a new aspect tests its 3D place and
        direction). Needs both images' gradients (``FrameContext``); without them, none."""
        out = np.zeros(len(model), bool)
        if context.left_gradients is None or context.right_gradients is None or not candidates.any():
            return out
        p, intr, T = self.params, context.intrinsics, context.T_camera_object
        k = np.flatnonzero(candidates)
        to_camera = invert(T)[:3, 3] - model.centers[k]
        to_camera /= np.maximum(np.linalg.norm(to_camera, axis=1, keepdims=True), 1e-12)
        k = k[np.einsum("nkj,nj->nk", model.extra["views"][k], to_camera).max(axis=1)
              <= np.cos(np.radians(p.view_step_deg))]
        along = np.linspace(-0.4, 0.4, IMAGE_SAMPLES)[None, :, None] * model.lengths[k, None, None]
        points = transform_points(T, (model.centers[k, None, :] + along * model.directions[k, None, :]).reshape(-1, 3))
        inside = in_both_images(points, intr, margin_px=IMAGE_SEARCH_PX + 1,
                                border_distance=context.border_distance).reshape(len(k), IMAGE_SAMPLES).all(axis=1)
        uv = [side.reshape(len(k), IMAGE_SAMPLES, 2) for side in intr.project(points)[:2]]     # left, right (px)
        with np.errstate(invalid="ignore"):     # ends behind the camera project to inf - inf: not ``inside``
            lines = [side[:, -1] - side[:, 0] for side in uv]
        spans = [np.linalg.norm(line, axis=1) for line in lines]
        normals = [np.column_stack([-line[:, 1], line[:, 0]]) / np.maximum(span, 1e-12)[:, None]
                   for line, span in zip(lines, spans)]
        off_rows = _clear_of_rows(lines[0], p)
        still_uv = intr.project(transform_points(T, still.centers[k]))[0]
        moved = np.abs(np.sum((still_uv - uv[0][:, IMAGE_SAMPLES // 2]) * normals[0], axis=1)) >= p.image_shift_px
        with np.errstate(invalid="ignore"):
            judged = np.flatnonzero(inside & off_rows & moved & (np.minimum(*spans) >= IMAGE_MIN_LENGTH_PX))
        ok = np.ones(len(judged), bool)
        for grads, side, normal in zip((context.left_gradients, context.right_gradients), uv, normals):
            found = edge_candidates(grads.gxy, np.ascontiguousarray(side[judged].reshape(-1, 2), np.float64),
                                    np.ascontiguousarray(np.repeat(normal[judged], IMAGE_SAMPLES, axis=0)),
                                    IMAGE_SEARCH_PX, IMAGE_MIN_GRADIENT, IMAGE_MIN_COS, 1)[:, 0]
            ok &= (np.abs(found) <= p.image_tolerance_px).reshape(len(judged), IMAGE_SAMPLES).mean(axis=1) >= p.image_share
        out[k[judged[ok]]] = True
        return out

    def expected(self, model: Segments, context: FrameContext, confirmed: np.ndarray | None = None) -> np.ndarray:
        """(N,) bool: the frame should have shown these model segments (see the module docstring); the
        image test of what the extraction missed only for those not ``confirmed`` (N,) bool."""
        p, intr = self.params, context.intrinsics
        T = context.T_camera_object
        ends = transform_points(T, model.endpoints().reshape(-1, 3))     # camera frame, as segments_in_both_images
        inside = in_both_images(ends, intr, border_distance=context.border_distance).reshape(-1, 2).all(axis=1)
        uv_left = intr.project(ends)[0]
        with np.errstate(invalid="ignore"):     # ends in the camera's plane project to infinity; not ``inside``
            d2 = (uv_left[1::2] - uv_left[0::2])
        not_critical = _clear_of_rows(d2, p)
        to_camera = (invert(T)[:3, 3] - model.centers).astype(np.float32)
        # cos(view, stored) >= cos(margin), without normalising: unused (zero) slots give 0
        projections = np.einsum("nkj,nj->nk", model.extra["views"], to_camera).max(axis=1)
        in_aspect = projections >= np.cos(np.radians(p.aspect_margin_deg)) * np.linalg.norm(to_camera, axis=1)
        expected = inside & not_critical & in_aspect
        if p.unextracted_no_miss and context.left_gradients is not None and context.extracted_left is not None:
            k = np.flatnonzero(expected if confirmed is None else expected & ~confirmed)
            expected[k[_unextracted(uv_left[0::2][k], uv_left[1::2][k], context, p)]] = False
        return expected


def _clear_of_rows(line_px: np.ndarray, p: LineModelParams) -> np.ndarray:
    """(N,) bool: projected segments (N, 2) px, end less start, at least 3 degrees farther from the image
    rows than the critical angle: extraction would have matched them along the rows (``expected``), and
    there the right image's line is not the left one's again (``image_confirmed``)."""
    return np.degrees(np.arctan2(np.abs(line_px[:, 1]), np.abs(line_px[:, 0]))) >= p.critical_angle_deg + 3.0


def _direction_of_planes(extra: dict, directions: np.ndarray, mi: np.ndarray, p: LineModelParams) -> np.ndarray:
    """(M, 3) the unit direction that each model segment ``mi``'s ``dir_info`` weighs least (its
    smallest eigenvector, signed as its ``directions`` row), and, in place, its ``inv_var_direction``
    raised to what the planes pin (the gap to the next eigenvalue; module docstring)."""
    values, vectors = np.linalg.eigh(extra["dir_info"][mi])       # ascending
    u = vectors[:, :, 0] * np.where(np.sum(vectors[:, :, 0] * directions[mi], axis=1) >= 0, 1.0, -1.0)[:, None]
    pinned = (values[:, 1] - values[:, 0]) / np.radians(p.reference_direction_sigma_deg) ** 2
    extra["inv_var_direction"][mi] = np.maximum(extra["inv_var_direction"][mi], pinned)
    return u


def _planes_figures(dir_info: np.ndarray, p: LineModelParams) -> tuple[np.ndarray, np.ndarray]:
    """Of direction information matrices (N, 3, 3): (N,) how far their planes miss one line (the least
    eigenvalue over the middle one) and (N,) the inverse variance (1/rad^2) that they pin the
    direction to (the gap between the two, in ``reference_direction_sigma_deg``'s weights)."""
    values = np.linalg.eigvalsh(dir_info)       # ascending
    return (values[:, 0] / np.maximum(values[:, 1], 1e-300),
            (values[:, 1] - values[:, 0]) / np.radians(p.reference_direction_sigma_deg) ** 2)


def _plane_sigma(length_px: np.ndarray, p: LineModelParams, context: FrameContext | None = None) -> np.ndarray:
    """(N,) rad: the sigma of the plane through the camera and a 2D line of ``length_px`` pixels, from
    its edge points' scatter (``line_sigma_px``) and the pose's rotation (``pose_rotation_sigma_deg``,
    or the frame's pose's own rotation sigma where ``context.pose_covariance`` gives a larger one)."""
    line_sigma = p.line_sigma_px * np.sqrt(12.0 / np.maximum(length_px, 1.0)) / np.maximum(length_px, 1.0)
    pose_rotation = np.radians(p.pose_rotation_sigma_deg)
    if context is not None and context.pose_covariance is not None:
        pose_rotation = max(pose_rotation, pose_rotation_sigma(context.pose_covariance))
    return np.hypot(line_sigma, pose_rotation)


def pose_sigmas(centers: np.ndarray, covariance: np.ndarray) -> tuple[np.ndarray, float]:
    """What a pose's error does to what it places: ``centers`` (N, 3) m, object frame, the pose
    ``T_camera_object = T exp(x)`` with x (rotation vector rad, translation m; object frame) of
    ``covariance`` (6, 6) about 0 (``motion.fuse``). Returns the position sigma (N,) m of each
    centre (the root-mean-square over the three axes of its displacement ``[p]_x theta - t``) and the
    rotation's sigma (rad, the root-mean-square over its three axes), which tilts directions and view
    planes. Why: with repaired poses (``--motion tracked``) a frame placed by a refinement on the model
    and one left at its recorded pose are some tenths of a degree and 1.5 degrees off; taken as exact,
    the latter's observations gate and weigh as the former's and land as twins beside their segments
    (``make motion``: 6 of 12 seeds within 0.02 of the exact poses' model without, 11 with; README).
    The root mean square over three axes is a simplification (the fused covariance is anisotropic:
    the images fix the lateral directions, the recorded poses depth); adding the full ``J C J^T`` to
    each observation's position covariance instead measured 9 of 12, median 0.009, worst 0.052
    (302 0.015 -> 0.025, 306 0.019 -> 0.032; tracked runs of the 12 seeds, 4 dithers, 2026-12-07):
    not kept."""
    p = np.asarray(centers, float).reshape(-1, 3)
    J = np.concatenate([skew(p), np.broadcast_to(-np.eye(3), (len(p), 3, 3))], axis=2)     # (N, 3, 6)
    position = np.sqrt(np.einsum("nij,jk,nik->n", J, covariance, J) / 3)
    return position, pose_rotation_sigma(covariance)


def pose_rotation_sigma(covariance: np.ndarray) -> float:
    """rad: a pose's rotation sigma, the root mean square over three axes of its (6, 6) ``covariance``
    (rotation first, as ``motion.fuse`` gives it)."""
    return float(np.sqrt(np.trace(covariance[:3, :3]) / 3))


def sigmas(segments: Segments) -> tuple[np.ndarray, np.ndarray] | None:
    """(position sigma (N,) m, direction sigma (N,) rad) of model segments (from their inverse-variance
    sums) or of extracted ones (``sigma_depth_m``, ``sigma_direction_rad``); None if they carry neither."""
    x = segments.extra
    if "inv_var_position" in x:
        return 1.0 / np.sqrt(x["inv_var_position"]), 1.0 / np.sqrt(x["inv_var_direction"])
    if "sigma_depth_m" in x and "sigma_direction_rad" in x:
        return x["sigma_depth_m"], x["sigma_direction_rad"]
    return None


def _new_views(ray: np.ndarray, max_views: int) -> np.ndarray:
    """(N, max_views, 3) float32 view sets holding ``ray``; float32 is ample for directions compared at
    degrees, and halves the largest part of a model segment's state."""
    views = np.zeros((len(ray), max_views, 3), np.float32)
    views[:, 0] = ray
    return views


def _add_view(views: np.ndarray, new: np.ndarray, step: float) -> np.ndarray:
    """Add unit directions ``new`` (M, 3; zero rows: nothing) to view sets (M, K, 3) where they are
    farther than ``step`` from every stored one: into a free slot, or else in place of the nearest."""
    views = views.copy()
    valid = views.any(axis=2)
    cosines = np.where(valid, np.einsum("mkj,mj->mk", views, new), -2.0)
    nearest = np.argmax(cosines, axis=1)
    novel = new.any(axis=1) & (cosines.max(axis=1) < np.cos(step))
    free = ~valid.all(axis=1)
    slot = np.where(free, np.argmax(~valid, axis=1), nearest)
    rows = np.flatnonzero(novel)
    views[rows, slot[rows]] = new[rows]
    return views


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.arccos(np.clip(np.sum(unit_or_zero(a) * unit_or_zero(b), axis=-1), -1.0, 1.0))


def _view_span(views: np.ndarray) -> np.ndarray:
    """(N,) the largest angle (rad) between two of each segment's stored unit views (N, K, 3; zero
    rows: free slots); 0 with one view."""
    present = views.any(axis=2)
    cos = np.einsum("nki,nli->nkl", views, views)
    both = present[:, :, None] & present[:, None, :]
    return np.arccos(np.clip(np.where(both, cos, 1.0).min(axis=(1, 2), initial=1.0), -1.0, 1.0))


UNSURE_CONFIDENCE = 0.49   # the written confidence of a segment held back by its direction's sigma


def direction_known(entities: Segments, rules: LineModelParams | None) -> np.ndarray:
    """(N,) bool: model segments whose direction sigma (``inv_var_direction``) is at most
    ``rules.max_direction_sigma_deg`` (every one for None, or without ``rules``), and at most
    ``rules.single_aspect_sigma_deg`` (None: no such rule) for those confirmed from one aspect only:
    their stored views all within ``rules.single_aspect_span_deg`` of each other (0: one stored
    view; ``to_model`` says why). The views' span is measured only where the one-aspect rule can
    decide (sigma between the two limits): it runs at every accumulation step.

    ``rules.plane_agreement`` (``accum accumulate --plane-agreement``; None: off): a direction is
    known only where the evidence that set it agrees, the least eigenvalue of ``dir_info`` (what its
    planes and stereo directions weigh against it) at most this share of the middle one (what pins it
    across). Why: a wrongly directed accepted segment typically claims 2 to 5 degrees from 3 to 5
    views whose planes do not meet on one line (a piece of a neighbouring edge, a 2D line biased at a
    corner); on sim_104 and dev_cube_small their ratio was 0.007 to 0.017, a right segment's 0.002 to
    0.005 (90th percentile). Measured (accumulation alone on ``make suite``'s recordings, 4 runs a
    row, 2026-12-07) with 0.006: precision median 0.963 -> 0.978, every row but the real teabox's at
    0.95 or more (sim_105 0.930 -> 0.961, dev_cube_small 0.908 -> 0.951; before, three rows under),
    but completeness median 0.673 -> 0.651, mean 0.691 -> 0.669, worst 0.359 -> 0.328: a choice for
    who needs every accepted segment right, so not the default. With the covariance gate's ceiling at
    3 s_o (``metric``) beside it: completeness mean 0.670, dev_cube_small 0.948. Milder ratios trade
    along the same line (same measure): 0.009 precision median 0.970, completeness median 0.670, mean
    0.680, worst 0.347, one row under 0.95 besides the teabox (dev_cube_small 0.937); 0.012 0.969 /
    0.670 / 0.685 / 0.350, two (sim_105 0.949, dev_cube_small 0.925)."""
    if rules is None or rules.max_direction_sigma_deg is None:
        return np.ones(len(entities), bool)
    inverse_variance = entities.extra["inv_var_direction"]
    known = inverse_variance >= np.radians(rules.max_direction_sigma_deg) ** -2.0
    if rules.plane_agreement is not None and "dir_info" in entities.extra:
        k = np.flatnonzero(known)
        known[k] = _planes_figures(entities.extra["dir_info"][k], rules)[0] <= rules.plane_agreement
    if rules.single_aspect_sigma_deg is not None:
        undecided = np.flatnonzero(known & (inverse_variance < np.radians(rules.single_aspect_sigma_deg) ** -2.0))
        known[undecided] = _more_than_one_aspect(entities.extra["views"][undecided], rules)
    return known


def _more_than_one_aspect(views: np.ndarray, rules: LineModelParams) -> np.ndarray:
    """(N,) bool: view sets (N, K, 3) spanning more than ``rules.single_aspect_span_deg``."""
    return _view_span(views) > np.radians(rules.single_aspect_span_deg) + 1e-9


def twin_candidates(model: Segments, p: LineModelParams) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j) (K,) int of model segments that lie as twins do (``_lying_as_twins``). Their centres
    are at most the longer one's length (and ``twin_across_m``) apart: the pairs of the shorter nine
    tenths within the reach of their longest, then those of the longest tenth with all (one reach for all,
    that of the model's longest segment, gave many times as many pairs to test)."""
    if len(model) < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    tree, reach = cKDTree(model.centers), model.lengths + p.twin_across_m
    short = float(np.quantile(reach, 0.9))
    pairs = tree.query_pairs(short, output_type="ndarray")
    long = np.flatnonzero(reach > short)
    far = cKDTree(model.centers[long]).sparse_distance_matrix(tree, float(reach.max()), output_type="ndarray")
    i = np.concatenate([pairs[:, 0], long[far["i"]]]).astype(np.int64)
    j = np.concatenate([pairs[:, 1], far["j"]]).astype(np.int64)
    key = np.unique((np.minimum(i, j) * len(model) + np.maximum(i, j))[i != j])      # each pair once
    i, j = key // len(model), key % len(model)
    near = _lying_as_twins(model, i, j, p)
    return i[near], j[near]


def _lying_as_twins(model: Segments, i: np.ndarray, j: np.ndarray, p: LineModelParams) -> np.ndarray:
    """(K,) bool: the pairs (i, j) overlap along their lines, within ``twin_across_m`` across each
    other's and ``twin_max_angle_deg`` in direction, neither more than ``max_extent`` times the other's
    length (``merge`` keeps a merged segment within that many of the absorbed one's lengths: a long
    segment would come out shorter)."""
    c, u, length = model.centers, model.directions, model.lengths
    rel = c[j] - c[i]
    along = np.sum(rel * u[i], axis=1)
    across = np.maximum(np.linalg.norm(rel - along[:, None] * u[i], axis=1),
                        np.linalg.norm(rel - np.sum(rel * u[j], axis=1)[:, None] * u[j], axis=1))
    return (across <= p.twin_across_m) & (np.abs(along) <= (length[i] + length[j]) / 2) & (
        d_o(u[i], u[j]) <= np.radians(p.twin_max_angle_deg)) & (
        np.maximum(length[i], length[j]) <= p.max_extent * np.minimum(length[i], length[j]))


def twins(model: Segments, i: np.ndarray, j: np.ndarray, settled: np.ndarray, p: LineModelParams):
    """(ok (K,) bool, cost (K,)) of the pairs (i, j) of model segments: twins of one edge (``merged_twins``),
    cost how far their planes together miss one line (``_planes_figures``). ``settled`` (N,) bool:
    segments already accepted with a known direction; a pair of two is left alone."""
    views = model.extra["views"]
    span = _view_span(np.concatenate([views[i], views[j]], axis=1))
    agreement, pinned = _planes_figures(model.extra["dir_info"][i] + model.extra["dir_info"][j], p)
    ok = _lying_as_twins(model, i, j, p) & ~(settled[i] & settled[j]) & (
        span >= np.radians(p.twin_min_view_deg)) & (agreement <= p.twin_plane_agreement)
    if p.max_direction_sigma_deg is not None:
        ok &= pinned >= np.radians(p.max_direction_sigma_deg) ** -2.0
    return ok, agreement


def merged_twins(core, p: LineModelParams):
    """A copy of the accumulator ``core`` (``accumulate.Accumulator`` of line segments) whose twins are
    merged, as the model is written (``LineAccumulation``); ``core`` is left as it is.

    Twins: two model segments of one edge built from different aspects, each holding the observations
    of its own. A short piece's stereo direction tilts in depth (on the suite's recordings 13 to 27 % of
    the matched length on edges is more than 10 degrees off), so the same edge seen a little later lands
    beside the segment, or off its direction by more than the gate, and starts one of its own; each
    twin then has one aspect, and its direction stays unsure (held back, ``to_model``) or it is never
    confirmed. But the plane through the camera and a piece holds the edge whatever its tilt, so the
    twins' planes together pin the direction that neither pins alone. A pair is merged (the more
    confident absorbs the other, as ``Accumulator._consolidate`` merges duplicates) where: they overlap
    along their lines and lie within ``twin_across_m`` across each other's (the devset's held twins lie
    3 to 4 mm apart) and ``twin_max_angle_deg`` of each other's direction; not both are accepted with a
    known direction (two such already cover their edge; merged too, they lowered the precision, which
    counts segments, on every devset row: the accepted model shrank by up to half, dev_wedge_far's 99
    segments to 45, and its wrong segments stayed);
    their views together span at least ``twin_min_view_deg`` (from one aspect their planes coincide and
    the merged direction would rest on their stereo directions alone: on sim_103 chains of such
    segments merged into 74 mm segments 16 degrees off); their summed ``dir_info`` has its least
    eigenvalue at most ``twin_plane_agreement`` times the middle one (the planes meet on one line) and
    pins the direction to ``max_direction_sigma_deg``. Whenever the model is written
    (``LineAccumulation.model``), not in the running accumulation (below).

    Measured on ``make suite``'s recordings (accumulation alone, 4 runs a row, 2026-12-07): completeness
    median 0.673 -> 0.693, mean 0.691 -> 0.708, worst row 0.359 -> 0.372 (every row the same or up,
    sim_103 0.830 -> 0.867, sim_107 0.718 -> 0.752, dev_steps 0.653 -> 0.676), precision median 0.963 ->
    0.966, mean 0.944 -> 0.941; three rows at 0.950 or 0.951 fell under 0.95 (sim_102 0.948, sim_111
    0.943, dev_wedge_far 0.948: by less than a standard deviation of their runs), sim_105 0.930 -> 0.920,
    the real teabox's surface precision 0.543 -> 0.538. Not hanging on the limits: 3 mm, 10 degrees and
    0.006 gave completeness median 0.692, mean 0.703, precision median 0.963. Merged in the running
    accumulation every fourth frame instead (same measure): completeness median 0.694, mean 0.704
    (dev_wedge_far 0.502), precision median 0.970: no better, and the accumulation's own rules then
    judge merged segments they did not build."""
    if len(core) < 2 or "dir_info" not in core.entities.extra:    # without ``view_planes`` there are no planes
        return core

    def same(accumulator, a, b):     # settled as of each round (a winner may have become so), of the pairs' only
        settled = np.zeros(len(accumulator), bool)
        k = np.unique(np.concatenate([a, b]))
        settled[k] = (accumulator.log_odds[k] >= 0) & direction_known(accumulator.entities.select(k), p)
        return twins(accumulator.entities, a, b, settled, p)

    return core.consolidated(*twin_candidates(core.entities, p), same)


def shared_directions(entities: Segments, settled: np.ndarray, rules: LineModelParams) -> Segments:
    """The ``settled`` (N,) bool segments (accepted, direction known) seen from more than one aspect
    (stored views spanning more than ``rules.single_aspect_span_deg``): their directions, pinned by
    distinct view planes, are the ones ``dominant_directions`` gives to others."""
    k = np.flatnonzero(settled)
    k = k[_more_than_one_aspect(entities.extra["views"][k], rules)]
    return Segments(entities.frame_id, entities.centers[k], entities.directions[k], entities.lengths[k],
                    np.ones(len(k)), np.ones(len(k), np.int64))


def _held_directed(entities: Segments, mean_view: np.ndarray, sigma: np.ndarray, confident: np.ndarray,
                   known: np.ndarray, rules: LineModelParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(taken (N,) bool, directions (N, 3), direction sigmas (N,) rad) of model segments (object frame)
    whose ``confident`` but not ``known`` direction takes the one the settled segments share
    (``dominant_directions``, not where a shared segment covers it); ``mean_view`` (N, 3) unit, towards
    the camera; ``sigma`` (N,) rad, the segments' own. Not those held back by ``plane_agreement``: their
    planes disagree, so there is no plane to hold a direction."""
    p = rules.dominant
    shared, held = shared_directions(entities, confident & known, rules), np.flatnonzero(confident & ~known)
    if rules.plane_agreement is not None:
        held = held[~direction_known(entities.select(held), replace(rules, plane_agreement=None))]
    taken, u, rms = dominant_directions(entities.directions[held], mean_view[held], sigma[held], shared, p)
    k, u, rms = held[taken], u[taken], rms[taken]
    free = ~covered(entities.centers[k], entities.lengths[k], u, shared, p)
    k = k[free]
    dominant, directions, sigma = np.zeros(len(entities), bool), entities.directions.copy(), sigma.copy()
    dominant[k], directions[k], sigma[k] = True, u[free], np.maximum(rms[free], np.radians(p.min_sigma_deg))
    return dominant, directions, sigma


def to_model(entities: Segments, confidence: np.ndarray, observations: np.ndarray,
             uncertainty: bool = True, rules: LineModelParams | None = None) -> Segments:
    """The model as written to files: segments with confidence and observation count, and
    per segment its mean viewing direction, cone half-angle (degrees), direction sigma (rad),
    ``direction_held`` (bool: confident, confidence >= 0.5, but held back by the rules below, so
    that ``evaluate_model`` can tell this loss from segments not confirmed) and (unless
    ``uncertainty`` is False: it inverts every segment's information, which tracking during
    accumulation does not need) the standard deviation of its position across its direction (m).

    ``rules`` (the run's ``LineModelParams``; None: none) decide which directions are sure enough
    (``direction_known``), and, with ``rules.dominant``, give held segments the direction that the
    accepted ones share where their view plane holds it (``dominant_directions``: then accepted,
    ``direction_dominant``). A segment whose direction sigma exceeds ``max_direction_sigma_deg`` is
    not accepted, whatever its confidence (written at most ``UNSURE_CONFIDENCE``): its existence is
    confirmed, its line is not. Such segments are seen from one aspect by pieces alone on their stretch, whose direction
    stereo leaves unsure (``stereo``: 1 degree, or a short line's fit, over the sine of their planes' angle); more aspects
    or a fitted stretch pin it. 5 degrees keeps the direction's two sigmas within the 10 degrees
    by which a segment counts as correct. ``make suite`` against none: precision median 0.944 ->
    0.963, completeness median 0.598 -> 0.589 (worst 0.263 -> 0.254); the real teabox's surface
    precision 0.324 -> 0.435 at the same completeness (0.638), dev_cube_small's precision 0.820 ->
    0.926. 7 degrees: 0.956 / 0.591, teabox 0.388; 4: 0.969 / 0.574 (worst 0.217); 3: 0.975 / 0.551.

    A segment confirmed from one aspect only (one stored view) must be sure to
    ``single_aspect_sigma_deg`` (LineModelParams: 1.5): the frames of one aspect see it through the
    same stereo geometry and the same neighbouring edges, so their errors do not average out, yet
    their information adds up as if they did. Measured on ``make suite``: of the accepted segments
    whose centre lies on an edge but whose direction is more than 10 degrees off it, most had one
    stored view (as their 2 to 4 confirmations came) and claimed a sigma of about 2 degrees.
    With a direction gate that forgives an observation's tilt within its view plane (``metric``;
    measured with its first, two-part form, which adds completeness and costs precision alone:
    medians 0.963 / 0.589 -> 0.938 / 0.607), precision / completeness medians 0.963 / 0.589 ->
    0.962 / 0.581 (worst precision 0.435 -> 0.575, the real teabox's, whose completeness falls
    0.638 -> 0.604); 2.5 degrees gave 0.947 / 0.584, this rule without the gate 0.984 / 0.563. On
    the real teabox, which turns little, the limit trades its surface precision for completeness
    (recorded poses; ``--motion tracked``): 1.5 degrees 0.575 / 0.604 (0.580 / 0.624), 2 0.544 /
    0.626 (0.540 / 0.680), 3 0.475 / 0.633 (0.496 / 0.728), none (5) 0.408 / 0.638 (0.421 /
    0.726); of the segments that 3 degrees adds to 1.5, a third lie on the body. With the gate by
    covariance of now: 0.609 / 0.646 at 1.5 degrees (``metric``).

    One aspect is every stored view within ``single_aspect_span_deg`` (15) of each other, not one
    stored view: views are stored 10 degrees apart (``view_step_deg``), and two views 10 degrees
    apart still see a short piece through nearly the same stereo geometry; most wrongly directed
    accepted segments had two views about 10 degrees apart. ``make suite`` against one stored view:
    precision / completeness medians 0.957 / 0.581 -> 0.980 / 0.576, rows with precision >= 0.95
    12 -> 16 of 19 (sim_106 0.932 -> 0.962, sim_107 0.943 -> 0.990, sim_111 0.941 -> 0.982,
    dev_steps 0.947 -> 0.957; dev_cube_small 0.857 -> 0.932), worst completeness 0.273 -> 0.257
    (sim_105 0.277 -> 0.257); the real teabox's surface precision / completeness 0.609 / 0.646 ->
    0.612 / 0.646. Storing views 15 degrees apart instead gave 0.976 / 0.590 but moved the aspect
    cones that tracking relies on (false tracked frames on the tracking scoreboard)."""
    extra = entities.extra
    known = direction_known(entities, rules)
    confident = np.asarray(confidence) >= 0.5
    views = extra["views"]
    mean_view = unit_or_zero(views.sum(axis=1))
    directions, sigma = entities.directions, 1.0 / np.sqrt(extra["inv_var_direction"])
    dominant = np.zeros(len(entities), bool)
    if rules is not None and rules.dominant is not None:
        dominant, directions, sigma = _held_directed(entities, mean_view, sigma, confident, known, rules)
        known = known | dominant
    held = ~known & confident
    confidence = np.where(known, confidence, np.minimum(confidence, UNSURE_CONFIDENCE))
    cosines = np.where(views.any(axis=2), np.einsum("nkj,nj->nk", views, mean_view), 1.0)
    spread = np.degrees(np.arccos(np.clip(cosines.min(axis=1, initial=1.0), -1, 1)))
    columns = {"direction_held": held, "direction_dominant": dominant, "view_direction": mean_view,
               "view_spread_deg": spread, "sigma_direction_rad": sigma}
    if uncertainty:
        covariance = np.linalg.inv(extra["info"]) if len(entities) else np.zeros((0, 3, 3))
        u = directions
        across = np.trace(covariance, axis1=1, axis2=2) - np.einsum("ni,nij,nj->n", u, covariance, u)
        columns["sigma_m"] = np.sqrt(np.maximum(across, 0) / 2)
    return Segments(entities.frame_id, entities.centers, directions, entities.lengths,
                    np.asarray(confidence, float), np.asarray(observations, np.int64), columns)


def _unextracted(start: np.ndarray, end: np.ndarray, context: FrameContext, p: LineModelParams) -> np.ndarray:
    """(N,) bool: of segments projected from ``start`` to ``end`` (N, 2 px, left image), those whose
    edge the left image shows (the median over 9 points of the gradient across the line within 1 px,
    ``edge_evidence``, at least the extraction's Canny high threshold) but along which no piece of
    ``context.extracted_left`` lies (``_pieces_on``): the extraction, not the object, failed there."""
    t = np.linspace(0.0, 1.0, 9)[None, :, None]
    uv = start[:, None, :] * (1 - t) + end[:, None, :] * t
    d = unit_or_zero(end - start)
    grads, intr = context.left_gradients, context.intrinsics
    shown = edge_evidence(grads, uv, np.stack([-d[:, 1], d[:, 0]], axis=1), (intr.width, intr.height)) \
        >= grads.gradient_threshold
    k = np.flatnonzero(shown)
    shown[k[np.unique(_pieces_on(start[k], end[k], context.extracted_left, p)[0])]] = False
    return shown


def _pieces_on(start: np.ndarray, end: np.ndarray, pieces: Segments2D, p: LineModelParams):
    """Pairs (i, j, cost) of projected segments ``start``-``end`` (N, 2 px each) and the ``pieces`` lying
    along them: within ``image_plane_gate_px`` across the projection and ``image_plane_gate_deg`` of its
    angle, the piece within its extent (``IMAGE_PLANE_END_SLACK_PX``); cost in [0, 2]."""
    length = np.linalg.norm(end - start, axis=1)
    usable = np.flatnonzero(np.isfinite(length) & (length >= 1.0))
    if not len(usable) or not len(pieces):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    middle, direction = (start + end)[usable] / 2, (end - start)[usable] / length[usable, None]
    reach = length[usable] / 2 + IMAGE_PLANE_END_SLACK_PX + p.image_plane_gate_px   # the farthest that passes
    i, j, along, across, cosine = pieces_along(middle, direction, reach, pieces)
    angle = np.degrees(np.arccos(np.clip(cosine, 0, 1)))
    on = (across <= p.image_plane_gate_px) & (angle <= p.image_plane_gate_deg) & \
        (np.abs(along) + pieces.lengths[j] / 2 <= length[usable][i] / 2 + IMAGE_PLANE_END_SLACK_PX)
    cost = (across / p.image_plane_gate_px) ** 2 + (angle / p.image_plane_gate_deg) ** 2
    return usable[i[on]], j[on], cost[on]


def planes_from_image(model: Segments, candidates: np.ndarray, pieces: Segments2D, context: FrameContext,
                      p: LineModelParams) -> np.ndarray:
    """Direction evidence without stereo, in place: the model segments ``candidates`` (N,) bool (object
    frame; ``LineAccumulation.step`` passes the confirmed ones whose direction is not yet known and
    that this frame did not confirm) each take the view plane of the left-image piece (``pieces``, this
    frame's pieces that no 3D segment used) lying along their projection: within
    ``image_plane_gate_px`` across it and ``image_plane_gate_deg`` of its angle, the piece within its
    extent (the nearest such piece). The plane through the camera and the piece is added to the
    segment's ``dir_info`` with the weight of a 3D observation of confidence ``image_plane_weight``,
    the direction is the planes' intersection again and its sigma what they pin; from the
    ``image_plane_min_frames``-th frame that gave a segment such a plane on, that frame's view is
    added to its aspects (``views``: the one-aspect rule of ``to_model``, and ``expected``). Needs
    ``view_planes`` (``dir_info``). Returns the indices of the segments that took a plane.

    Why: a piece that stereo left unmatched (no right piece, an ambiguous one, a polarity flip) still
    fixes the plane its edge lies in, and a plane from another aspect is what a segment seen from one
    aspect lacks (``to_model``): its direction is the intersection of planes as far apart as the
    object turned. A segment 10 degrees off in depth projects within a few degrees of its edge in a
    view 20 degrees away, so the plane of the true edge is found and corrects it. Measured on ``make
    suite`` (at 02a71e9): completeness median 0.624 -> 0.642 (12 rows up, the teabox down 0.007),
    worst 0.271 -> 0.280, precision median 0.971 -> 0.969 (6 rows up, 4 down; under 0.95 3 -> 4 rows,
    sim_106 0.956 -> 0.947); its view counting from the first frame: completeness 0.642, precision
    median 0.958 (6 rows under 0.95); from the third: 0.629 / 0.972; every left piece, matched ones
    too: 0.649 / 0.957 (7 rows under 0.95); gates of 1 px and 2 degrees lost completeness on the
    devset (0.547 against 0.549 on its median row) for no precision. The planes' agreement does not
    tell a wrong direction from a right one (the chi-square of ``dir_info`` over its weight: median
    1.46 for accepted right segments, 1.37 for wrong ones): the errors are shared, not random. Measured
    and not kept (``make suite``, 4 runs a row, 2026-12-07): a segment that no piece lies along takes
    the plane of a line fitted to the gradient maxima found across 9 points of its projection (the
    tracker's edge search, 3 px, at least 7 found, 0.3 px RMS): completeness mean 0.691 -> 0.700,
    worst 0.359 -> 0.375, but precision median 0.963 -> 0.956, rows under 0.95 three -> eight (sim_111
    0.951 -> 0.896); the angle gate widened by each segment's own direction sigma (2 sigma, 3 to 20
    degrees): 65 -> 73 planes over dev_wedge_far's 24 frames, its model the same. Nor kept (same
    measure, 2026-12-07): a segment confirmed by an observation that merged into another taking that
    observation's plane and view too (the confirmed correct segments held back for their direction
    lie two to five on one edge, sharing its observations): completeness mean 0.691 -> 0.698, but
    precision median 0.963 -> 0.953, rows under 0.95 three -> nine; with ``plane_agreement`` 0.006
    beside it 0.975 / 0.667 against that option's 0.978 / 0.669 alone. Nor merging such duplicates
    wherever they lie in the model (a tree over all centres each frame): every figure within 0.005."""
    idx = np.flatnonzero(candidates)
    if not len(idx) or not len(pieces):
        return idx[:0]
    T, intr = context.T_camera_object, context.intrinsics
    uv, _, z = intr.project(transform_points(T, model.select(idx).endpoints().reshape(-1, 3)))
    in_front = (z[0::2] > 0) & (z[1::2] > 0)
    idx, uv = idx[in_front], uv.reshape(-1, 2, 2)[in_front]
    i, j, cost = _pieces_on(uv[:, 0], uv[:, 1], pieces, p)
    nearest = best_per_key(i, cost)
    i, j = i[nearest], j[nearest]
    mi = idx[i]
    # the piece's plane through the camera: normal of its two ends' rays, into the object frame
    ends = pieces.endpoints()[j]
    normal = unit_or_zero(view_plane_normals(ends[:, 0], ends[:, 1], intr)) @ T[:3, :3]
    reference = np.radians(p.reference_direction_sigma_deg)
    x = model.extra
    x["dir_info"][mi] += (p.image_plane_weight * (reference / _plane_sigma(pieces.lengths[j], p, context)) ** 2
                          )[:, None, None] * outer(normal)
    model.directions[mi] = _direction_of_planes(x, model.directions, mi, p)
    x["image_planes"][mi] += 1
    counted = mi[x["image_planes"][mi] >= p.image_plane_min_frames]
    x["views"][counted] = _add_view(x["views"][counted], unit_or_zero(invert(T)[:3, 3] - model.centers[counted]),
                                    np.radians(p.view_step_deg))
    return mi


IMAGE_PLANE_END_SLACK_PX = 2.0   # a piece may reach this far beyond a projected segment's ends (Canny's corners)
