"""Pictures of line models without a viewer (OpenCV drawing only), after the
paper's Figures 1 and 5: segments projected into a pinhole view, black on
white, the grey level telling the confidence (dark = confident).

Images are (H, W, 3) uint8 in OpenCV's BGR order. Pixel coordinates follow the
package convention (origin at the centre of the top-left pixel), as do
OpenCV's drawing functions.
"""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np

from .atomic import opened
from .errors import AccumError
from .geometry import make_transform, transform_points

NEAR = 1e-3          # metres: segments with an endpoint nearer than this (or behind the camera) are not drawn
MAX_GREY = 230       # the lightest grey drawn, so that tentative segments stay visible on white
SHIFT = 4            # cv2 fixed-point bits: endpoints are drawn with 1/16 px precision
FONT = cv2.FONT_HERSHEY_SIMPLEX
LEGEND_BAND = 44     # px at the bottom kept free for the legend when the view is fitted to the model
TRUTH_BGR = (255, 0, 255)   # a truth's edges, under the model, as Rerun's view draws them (magenta)


def confidence_grey(confidence: np.ndarray) -> np.ndarray:
    """(N,) grey levels 255 * (1 - confidence), clipped to [0, MAX_GREY]."""
    return np.clip(255.0 * (1.0 - np.asarray(confidence, float)), 0, MAX_GREY)


def draw_segments(canvas: np.ndarray, endpoints: np.ndarray, K: np.ndarray, grey: np.ndarray,
                  thickness: int = 2, bgr: tuple | None = None) -> None:
    """Draw segments into ``canvas`` (H, W, 3) uint8, in place.

    endpoints: (N, 2, 3) metres in the camera frame of ``K`` (3, 3), optical axes;
    grey: (N,) grey level per segment, or one colour ``bgr`` for all. Lighter segments are drawn
    first, so darker (more confident) ones lie on top. Anti-aliased lines, ``thickness`` px.
    """
    if len(endpoints) == 0:
        return
    z = endpoints[..., 2]
    keep = (z > NEAR).all(axis=1)
    uvw = endpoints[keep] @ K.T
    uv = uvw[..., :2] / uvw[..., 2:]
    pts = np.rint(np.clip(uv, -1e5, 1e5) * (1 << SHIFT)).astype(np.int64)
    levels = np.asarray(grey, float)[keep]
    for k in np.argsort(-levels, kind="stable"):
        g = int(round(levels[k]))
        cv2.line(canvas, tuple(map(int, pts[k, 0])), tuple(map(int, pts[k, 1])), bgr or (g, g, g), thickness,
                 cv2.LINE_AA, SHIFT)


def fit_intrinsics(points_view: np.ndarray, size: tuple[int, int], fill: float = 0.8) -> np.ndarray:
    """(3, 3) K with the principal point at the image centre and the focal length (px)
    at which ``points_view`` (N, 3), metres in front of the camera, span ``fill`` of
    the width or the height of a ``size`` = (W, H) picture."""
    w, h = size
    front = points_view[points_view[:, 2] > NEAR]
    if len(front):
        x, y = np.abs(front[:, :2] / front[:, 2:]).max(axis=0)
    else:
        x = y = 0.0
    f = min(fill * w / 2 / max(x, 1e-9), fill * h / 2 / max(y, 1e-9), 1e6)
    return np.array([[f, 0.0, (w - 1) / 2], [0.0, f, (h - 1) / 2], [0.0, 0.0, 1.0]])


def default_view(points: np.ndarray, tilt_deg: float = 25.0) -> np.ndarray:
    """T_view_object (4, 4) of a virtual optical camera looking at the centroid of
    ``points`` (N, 3), object frame, along the object's +z, tilted ``tilt_deg``
    so it looks from the object's -y side ("slightly from above" when y points
    down), from 3x the points' radius."""
    centroid = points.mean(axis=0) if len(points) else np.zeros(3)
    radius = float(np.linalg.norm(points - centroid, axis=1).max()) if len(points) else 0.0
    radius = max(radius, 1e-3)
    t = np.radians(tilt_deg)
    forward = np.array([0.0, np.sin(t), np.cos(t)])
    right = np.array([1.0, 0.0, 0.0])
    R_view_object = np.stack([right, np.cross(forward, right), forward])
    eye = centroid - 3.0 * radius * forward
    return make_transform(R_view_object, -R_view_object @ eye)


def _nice_length(metres: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``metres``."""
    exponent = np.floor(np.log10(metres))
    mantissa = max(m for m in (1, 2, 5) if m * 10 ** exponent <= metres * (1 + 1e-9))
    return float(mantissa * 10 ** exponent)


def _legend(canvas: np.ndarray, n: int, accepted: int, metres_per_px: float | None) -> None:
    """Counts, a confidence ramp and a scale bar in the bottom left corner."""
    h, w = canvas.shape[:2]
    scale = max(0.35, min(w, h) / 1400)
    cv2.putText(canvas, f"{n} segments, {accepted} accepted", (8, h - 30), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    ramp = confidence_grey(np.linspace(0, 1, 100)).astype(np.uint8)
    canvas[h - 20:h - 12, 8:108] = ramp[None, :, None]
    cv2.putText(canvas, "confidence 0..1", (114, h - 12), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    if metres_per_px:
        length = _nice_length(0.2 * w * metres_per_px)
        px = int(round(length / metres_per_px))
        cv2.line(canvas, (w - 12 - px, h - 14), (w - 12, h - 14), (0, 0, 0), 2)
        label = f"{length * 1000:g} mm" if length < 1 else f"{length:g} m"
        cv2.putText(canvas, label, (w - 12 - px, h - 22), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)


def _fit_points(model) -> np.ndarray:
    """(M, 3) endpoints a default view is fitted to: the accepted segments' when there are any
    (tentative ones are mostly background clutter and may fall outside the picture), else all."""
    ends = model.endpoints()
    return (ends[model.accepted] if model.accepted.any() else ends).reshape(-1, 3)


def fitted_view(model, size: tuple[int, int] = (640, 480)) -> tuple[np.ndarray, np.ndarray]:
    """(T_view_object (4, 4), K (3, 3)): ``default_view`` and ``fit_intrinsics`` for a
    (W, H) = ``size`` picture, fitted to the accepted segments (all if none is accepted)."""
    points = _fit_points(model)
    T = default_view(points)
    return T, fit_intrinsics(transform_points(T, points), size)


def render_model(model, size: tuple[int, int] = (640, 480), T_view_object: np.ndarray | None = None,
                 intrinsics=None, legend: bool = True, truth_ends: np.ndarray | None = None) -> np.ndarray:
    """The model's segments (object frame) seen by a pinhole camera: (H, W, 3) uint8, white background.

    size: (W, H) px. T_view_object: pose of the object in the (optical) view
    camera, by default ``default_view``. intrinsics: anything with a (3, 3)
    ``K`` (e.g. ``StereoIntrinsics``); by default a K at which the accepted
    segments (all if none is) fill 80% of the picture above the legend.
    Grey = 255 (1 - confidence), clipped to [0, 230]; ``legend`` adds counts, a
    confidence ramp and a scale bar (at the median depth of the segments fitted to). ``truth_ends``:
    (M, 2, 3) metres, object frame: a truth's edges, drawn thin in magenta under the model.
    """
    w, h = size
    points = _fit_points(model)
    T = default_view(points) if T_view_object is None else T_view_object
    K = intrinsics.K if intrinsics is not None else \
        fit_intrinsics(transform_points(T, points), (w, h - LEGEND_BAND if legend else h))
    ends_view = transform_points(T, model.endpoints().reshape(-1, 3)).reshape(-1, 2, 3)
    canvas = np.full((h, w, 3), 255, np.uint8)
    _draw_truth(canvas, truth_ends, T, K)
    draw_segments(canvas, ends_view, K, confidence_grey(model.confidence))
    if legend:
        z = transform_points(T, points)[:, 2]
        z = z[z > NEAR]
        _legend(canvas, len(model), int(model.accepted.sum()), float(np.median(z)) / K[0, 0] if len(z) else None)
    return canvas


def _draw_truth(canvas: np.ndarray, truth_ends: np.ndarray | None, T_view_object: np.ndarray, K: np.ndarray) -> None:
    """A truth's edges ((M, 2, 3) metres, object frame) thin in magenta, in place."""
    if truth_ends is not None and len(truth_ends):
        ends = transform_points(T_view_object, truth_ends.reshape(-1, 3)).reshape(-1, 2, 3)
        draw_segments(canvas, ends, K, np.zeros(len(ends)), 1, TRUTH_BGR)


def _side_by_side(panels: list) -> np.ndarray:
    """Panels of one height side by side, 4 px of grey between them."""
    gap = np.full((panels[0].shape[0], 4, 3), 200, np.uint8)
    return np.hstack([x for panel in panels for x in (panel, gap)][:-1])


def render_models(models: dict, size: tuple[int, int] = (640, 480), truth_ends: np.ndarray | None = None) -> np.ndarray:
    """Several models (name -> ``Segments``, one object frame) side by side in one view fitted to all
    of their accepted segments, each titled with its name, over a truth's edges if given (as
    ``render_model``): (H + 22, n W + 4 (n - 1), 3) uint8."""
    union = np.concatenate([_fit_points(m) for m in models.values()])
    T = default_view(union)
    K = fit_intrinsics(transform_points(T, union), (size[0], size[1] - LEGEND_BAND))
    view = SimpleNamespace(K=K)   # what render_model takes as intrinsics
    return _side_by_side([_titled(render_model(m, size, T, view, truth_ends=truth_ends), name)
                          for name, m in models.items()])


def _titled(image: np.ndarray, title: str, bar: int = 22) -> np.ndarray:
    """``image`` (H, W, 3) under a white bar with ``title``."""
    head = np.full((bar, image.shape[1], 3), 255, np.uint8)
    width = cv2.getTextSize(title, FONT, 0.45, 1)[0][0]
    scale = 0.45 * min(1.0, (image.shape[1] - 8) / width)  # shrink to fit narrow panels
    cv2.putText(head, title, (4, bar - 7), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return np.vstack([head, image])


def render_frame_panel(frame, result, model, T_camera_object: np.ndarray, truth_ends: np.ndarray | None = None,
                       more: dict | None = None, name: str = "model") -> np.ndarray:
    """Three panels side by side (the paper's Figure 5), each (H + 22, W) with a title:
    the left input image; the frame's 3D segments (``result.segments``, left camera
    frame) projected into the left camera, black on white; the model (object frame)
    projected into the same camera at ``T_camera_object``, grey by confidence, over a
    truth's edges (``truth_ends``, (M, 2, 3) metres, object frame) in magenta if given;
    then one more such panel per model of ``more`` (name -> ``Segments``); ``name``: the first model's title.
    Returns (H + 22, (3 + len(more)) W + 4 (2 + len(more)), 3) uint8."""
    K = frame.intrinsics.K
    h, w = frame.left.shape
    thickness = 2 if w >= 320 else 1
    image = cv2.cvtColor(frame.left, cv2.COLOR_GRAY2BGR)
    extracted = np.full((h, w, 3), 255, np.uint8)
    draw_segments(extracted, result.segments.endpoints(), K, np.zeros(len(result.segments)), thickness)
    panels = [_titled(image, f"frame {frame.index}"), _titled(extracted, f"{len(result.segments)} 3D segments")]
    for title, shown in {name: model, **(more or {})}.items():
        projected = np.full((h, w, 3), 255, np.uint8)
        _draw_truth(projected, truth_ends, T_camera_object, K)
        ends = transform_points(T_camera_object, shown.endpoints().reshape(-1, 3)).reshape(-1, 2, 3)
        draw_segments(projected, ends, K, confidence_grey(shown.confidence), thickness)
        panels.append(_titled(projected, f"{title}: {int(shown.accepted.sum())}/{len(shown)} accepted"))
    return _side_by_side(panels)


def write_png(target, image: np.ndarray) -> None:
    """Write ``image`` (H, W) or (H, W, 3) BGR uint8 as a PNG to a path (atomically) or an open binary file."""
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise AccumError(f"{target}: could not encode the image as PNG")
    with opened(target, "wb") as f:
        f.write(data.tobytes())
