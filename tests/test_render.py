"""Pictures of models and frames (accumcli.render), on synthetic data.

The builders here (a wire cube, a frame seeing it) are also used by test_visualize.
"""

from __future__ import annotations

import cv2
import numpy as np

from accumcli.extract import FrameSegments
from accumcli.geometry import make_transform
from accumcli.lines2d import Segments2D
from accumcli.recording import StereoFrame, StereoIntrinsics
from accumcli.render import LEGEND_BAND, fitted_view, render_frame_panel, render_model, write_png
from accumcli.segments import Segments

INTRINSICS = StereoIntrinsics(fx=60.0, fy=60.0, cx=31.5, cy=23.5, baseline=0.08, width=64, height=48)


def cube_model(side: float = 0.1, piece: float = 0.02, confident_faces=(-1,)) -> Segments:
    """Local segments (object frame, metres) along the 12 edges of a cube centred at the origin.
    Edges on the faces z = side/2 * f for f in ``confident_faces`` get confidence 0.95, the
    others 0.2."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * side / 2
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if np.sum(corners[i] != corners[j]) == 1]
    centers, directions, confidence = [], [], []
    n = int(round(side / piece))
    for i, j in edges:
        a, b = corners[i], corners[j]
        t = (np.arange(n) + 0.5) / n
        centers.append(a + t[:, None] * (b - a))
        directions.append(np.repeat([(b - a) / side], n, axis=0))
        on_face = any(a[2] == b[2] == f * side / 2 for f in confident_faces)
        confidence.append(np.full(n, 0.95 if on_face else 0.2))
    centers, directions, confidence = (np.concatenate(x) for x in (centers, directions, confidence))
    m = len(centers)
    return Segments("object", centers, directions, np.full(m, piece), confidence, np.ones(m, np.int64))


def camera_pose(i: int) -> np.ndarray:
    """T_camera_object of frame ``i``: the cube 0.45 m ahead, turning a few degrees per frame."""
    a = np.radians(20 + 5 * i)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return make_transform(R, [0.005 * i, 0.0, 0.45])


def segments_2d(uv: np.ndarray) -> Segments2D:
    """2D segments from endpoints ``uv`` (N, 2, 2) px."""
    d = uv[:, 1] - uv[:, 0]
    lengths = np.linalg.norm(d, axis=1)
    n = len(uv)
    directions = d / np.maximum(lengths, 1e-9)[:, None]
    return Segments2D(centers=uv.mean(axis=1), directions=directions, lengths=lengths, polarity=np.ones(n, np.int8),
                      contrast=np.full(n, 10.0), line_id=np.arange(n), t=np.zeros(n), line_direction=directions)


def frame_and_extraction(i: int, model: Segments | None = None) -> tuple[StereoFrame, FrameSegments]:
    """A 64x48 stereo frame of the cube at ``camera_pose(i)`` and an extraction that saw every
    cube segment (3D in the left camera frame) plus one unmatched 2D segment per image."""
    model = cube_model() if model is None else model
    T = camera_pose(i)
    seen = model.transformed(T, "camera_left")
    ends = seen.endpoints().reshape(-1, 3)
    uv_left, uv_right, _ = INTRINSICS.project(ends)
    extra = np.array([[[2.0, 2.0], [12.0, 2.0]]])
    left = segments_2d(np.concatenate([uv_left.reshape(-1, 2, 2), extra]))
    right = segments_2d(np.concatenate([uv_right.reshape(-1, 2, 2), extra]))
    images = []
    for uv in (left.endpoints(), right.endpoints()):
        img = np.full((48, 64), 40, np.uint8)
        for a, b in np.rint(uv).astype(int):
            cv2.line(img, tuple(map(int, a)), tuple(map(int, b)), 220, 1)
        images.append(img)
    n = len(seen)
    frame = StereoFrame(i, 1_000_000_000 + i * 100_000_000, images[0], images[1], INTRINSICS, T)
    result = FrameSegments(i, frame.timestamp_ns, seen, left, right, np.arange(n), np.arange(n),
                           {"left_2d": n + 1, "right_2d": n + 1, "critical": 0, "unmatched": 1, "segments": n})
    return frame, result


def non_white(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels that are not white."""
    return (image < 250).any(axis=2)


def test_render_model_not_blank_and_fits_the_accepted_segments():
    model = cube_model()
    image = render_model(model, size=(320, 240), legend=False)
    assert image.shape == (240, 320, 3) and image.dtype == np.uint8
    assert non_white(image).sum() > 500
    rows, cols = np.nonzero(image.mean(axis=2) < 100)  # accepted segments only (tentative ones are light)
    width, height = (cols.max() - cols.min()) / 320, (rows.max() - rows.min()) / 240
    assert 0.7 < max(width, height) < 0.85  # fitted to ~80% of the picture
    assert abs((cols.max() + cols.min()) / 2 - 159.5) < 10 and abs((rows.max() + rows.min()) / 2 - 119.5) < 10


def test_default_view_fits_all_segments_without_accepted_ones():
    model = cube_model(confident_faces=())
    assert not model.accepted.any()
    rows, cols = np.nonzero(non_white(render_model(model, size=(320, 240), legend=False)))
    assert 0.7 < max((cols.max() - cols.min()) / 320, (rows.max() - rows.min()) / 240) < 0.85


def fixed_view(model: Segments, size=(320, 240)):
    """(T_view_object, an object with K): the default view of ``model``, fixed so that
    renderings of parts of it line up with renderings of all of it."""
    T, K = fitted_view(model, size)
    return T, type("Pinhole", (), {"K": K})()


def test_confident_segments_are_darker_than_tentative_ones():
    model = cube_model()
    accepted = model.accepted
    assert accepted.any() and (~accepted).any()
    T, pinhole = fixed_view(model)
    image = render_model(model, (320, 240), T, pinhole, legend=False)
    on_accepted = non_white(render_model(model.select(accepted), (320, 240), T, pinhole, legend=False))
    on_tentative = non_white(render_model(model.select(~accepted), (320, 240), T, pinhole, legend=False))
    only_accepted, only_tentative = on_accepted & ~on_tentative, on_tentative & ~on_accepted
    assert only_accepted.sum() > 100 and only_tentative.sum() > 100
    grey = image.mean(axis=2)
    assert grey[only_accepted].mean() + 60 < grey[only_tentative].mean()
    assert grey[only_accepted].min() < 40  # confidence 0.95 -> grey 13 at the line's core
    assert grey[only_tentative].min() > 150  # confidence 0.2 -> grey 204, never black


def test_accepted_segments_lie_on_top_where_they_cross():
    model = cube_model()
    T, pinhole = fixed_view(model)
    full = render_model(model, (320, 240), T, pinhole, legend=False).mean(axis=2)
    only = render_model(model.select(model.accepted), (320, 240), T, pinhole, legend=False).mean(axis=2)
    core = only < 60
    assert core.sum() > 50
    assert np.abs(full[core] - only[core]).max() < 40  # tentative ones, drawn first, never lighten them


def test_legend_keeps_clear_of_the_model():
    model = cube_model()
    T, pinhole = fixed_view(model, (320, 240 - LEGEND_BAND))
    model_only = render_model(model, (320, 240), T, pinhole, legend=False)
    with_legend = render_model(model, (320, 240))
    assert not non_white(model_only)[-LEGEND_BAND:].any()
    assert np.array_equal(with_legend[:-LEGEND_BAND], model_only[:-LEGEND_BAND])
    assert non_white(with_legend)[-LEGEND_BAND:].sum() > 200  # counts, ramp, scale bar


def test_empty_model_renders_a_white_picture():
    image = render_model(cube_model().select(np.zeros(60, bool)), (200, 150), legend=False)
    assert image.shape == (150, 200, 3) and (image == 255).all()


def test_frame_panel(tmp_path):
    model = cube_model()
    frame, result = frame_and_extraction(2, model)
    panel = render_frame_panel(frame, result, model, frame.T_camera_object)
    assert panel.shape == (48 + 22, 3 * 64 + 8, 3) and panel.dtype == np.uint8
    body = panel[22:]
    image, extracted, projected = body[:, :64], body[:, 68:132], body[:, 136:200]
    assert np.array_equal(image[..., 0], frame.left)
    assert non_white(extracted).sum() > 100 and non_white(projected).sum() > 100
    assert extracted.min() < 60  # black lines
    # The extraction is the model seen from the same pose: both drawings cover the same pixels.
    a, b = non_white(extracted), non_white(projected)
    assert (a & b).sum() > 0.7 * min(a.sum(), b.sum())
    assert non_white(panel[:22]).any()  # titles
    path = tmp_path / "panel.png"
    write_png(path, panel)
    assert np.array_equal(cv2.imread(str(path)), panel)


def test_several_models_side_by_side_in_one_view_over_the_truth():
    """Two models in one view (fitted to both), titled, each over the truth's edges in magenta: the
    model of the cube's half lies where that half lies in the whole cube's panel."""
    from accumcli.render import render_models

    whole = cube_model()
    half = whole.select(whole.centers[:, 0] > 0)
    image = render_models({"whole": whole, "half": half}, size=(320, 240), truth_ends=whole.endpoints())
    assert image.shape == (240 + 22, 2 * 320 + 4, 3)
    left, right = image[22:, :320], image[22:, 324:]
    magenta = (image[..., 1] < 120) & (image[..., 0] > 200) & (image[..., 2] > 200)
    assert magenta[22:, 324:].sum() > 300 and magenta[22:, :320].sum() == 0   # the whole model covers all the truth
    dark_half = right.mean(axis=2) < 100
    assert dark_half.any() and (left.mean(axis=2) < 100)[dark_half].mean() > 0.9   # same view: it lies on the whole
