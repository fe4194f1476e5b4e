"""2D local line segments in one rectified image (the paper's section 2.2.1).

A local segment exists where there is *global support* (it lies on a line of
an orientation-sensitive Hough transform) *and local support* (along that line
the gradient is strong and its orientation agrees with the line's normal):

1. Gradients: Sobel on the slightly blurred image (``blur_sigma``), in grey levels per pixel.
   Edge pixels are Canny's (non-maximum suppressed, hysteresis); each is moved
   to sub-pixel position by a parabola through the gradient magnitude along
   the gradient direction.
2. Hough: every edge pixel votes, weighted by its gradient magnitude and a
   triangular kernel, only for line normals within ``vote_window_deg`` of its
   own orientation (the smoothed structure tensor's, steadier than its
   gradient's; undirected: normal angles in [0, 180), the rho axis mirrored at
   the wrap). Peaks are local maxima of the accumulator.
3. Each edge pixel joins the candidate line nearest to it among the peaks its
   own votes landed near. A line's pixels are fitted (weighted total least
   squares); along it, runs of supporting pixels (same polarity, small gaps)
   are cut into pieces of ``segment_length_px`` that span the run. A run needs
   ``min_fill`` of the pixels a full edge of its orientation gives on the
   pixel grid. Each piece is a local segment, fitted first to its sub-pixel
   edge points and then refined on the gradient itself (``refine_on_gradient``).

The detectors (``DETECTORS``, ``LineParams.detector``): ``hough`` (the above, the paper's);
``chains`` (the default, ``edge_chains``: straight edge chains, for short and crowded edges,
where Hough's smoothed orientations and vote windows lose them); ``lsd`` (OpenCV's line segment
detector), ``fld`` (opencv-contrib's FastLineDetector) and ``ed`` (its EdgeDrawing lines), whose
line segments ``pieces_on_lines`` cuts into local segments. On the suite (benchmarks/suite.py,
19 rows) ``chains`` against ``hough`` gave, on the median row, correct 3D 0.37 of the seen length
(0.29), near-object precision 0.81 (0.75), completeness 0.49 (0.39), accumulated precision 0.90
(0.92). On the devset's five rows ``lsd`` gave less correct 3D (median 0.26 against 0.30) but a
higher accumulated precision (0.94 against 0.88); ``ed`` and ``fld`` less of both.

The blur before the gradients (``blur_sigma``, ``--gradient-blur``) is 0.5 px (1.0 until 2026-12-06).
A camera's optics blur its images already (0.5 to 1.2 px in the simulator and the devset), and
every more pixel of blur flattens an edge's gradient peak (a step of h grey levels peaks at about
h / (2.5 sigma) grey levels per pixel, sigma the optics', the blur's and Sobel's together) and
merges neighbouring edges: with 1.0 a step of 10 grey levels (the truth counts 6 and more as seen)
peaks under Canny's 3 grey levels per pixel and is missed on most of its length
(``tests/test_lines2d.py``). On ``make suite`` (2026-12-06, 4 runs a row; precision / completeness
means over the 19 rows, rows under a precision of 0.95): 1.0 0.939 / 0.621, 6 rows; 0.85 0.932 /
0.635, 7 rows; 0.7 0.942 / 0.642, 5 rows; 0.5 0.947 / 0.666, 3 rows (median 0.975 / 0.673, worst
row's completeness 0.269 -> 0.306, single-frame near-object precision median 0.761 -> 0.814, the
teabox 0.544 / 0.615 against 0.574 / 0.508); 0.3 and 0 0.943 / 0.667, 4 rows (the teabox 0.541 /
0.556 and 0.533 / 0.569). With Canny's threshold at 3.5 too, 0.949 / 0.665, 3 rows; at 2.5, 0.949 /
0.666, 4 rows (every row within 0.015 but dev_cube_small's precision, 0.889 -> 0.913): the threshold
is flat from 2.5 to 3.5, and stays 3.0 (3.5 extracts 3 % faster: too little to move it). The support
rules of ``edge_chains`` and its end taper were set with 1.0 (their tests keep it). fld's and ed's
own line finding keeps the blur it was measured with (``OPENCV_LINE_BLUR``), tracking its own
(``TrackParams.blur_sigma``, 1.0).

Pixel coordinates are (u, v) = (column, row), origin at the centre of the
top-left pixel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import cv2
import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .grouping import group_range
from .chain_kernel import line_order
from .group_kernel import group_line_fit, line_coordinates, magnitude as magnitude_image, piece_groups, supporting_runs
from .profile_kernel import cut_grid, cut_peaks
from .pair_kernel import junction_growth


@dataclass(frozen=True)
class LineParams:
    """Parameters of 2D extraction (defaults suit 640x480 8-bit images)."""

    segment_length_px: float = 15.0
    blur_sigma: float = 0.5             # of the image before its gradients, px (module docstring)
    tensor_sigma: float = 1.5         # smoothing of the structure tensor that orients the votes
    gradient_threshold: float = 3.0   # grey levels per pixel, Canny's high threshold (low = half)
    angle_step_deg: float = 1.0       # Hough normal-angle bin
    vote_window_deg: float = 3.0      # each pixel votes within +- this of its own orientation
    min_line_support_px: float = 12.0  # a Hough peak needs this many pixels' worth of threshold-strength votes
    max_lines: int = 600              # per pass
    hough_passes: int = 3
    min_fill: float = 0.6
    max_line_distance_px: float = 1.5  # pixels farther from their fitted line are dropped
    max_gap_px: float = 3.0           # a longer gap along a line ends a run of support
    end_extension_px: float = 2.5     # pieces reach this far beyond a run's first and last pixel
    junction_radius_px: float = 7.0   # runs ending this near another line's run meet it at the corner
    chain_min_support_px: float = 10.0  # chains: a shorter straight chain is not cut at a bend
    piece_min_support_px: float = 8.0   # a piece needs a run of support of this span,
    corner_piece_min_support_px: float = 7.0   # or this one grown to a corner at both ends (at most the above)
    chain_end_taper_px: float = 2.5   # chains: edge pixels this near a chain's end weigh less in its direction
    detector: str = "chains"


@dataclass
class Segments2D:
    """Local 2D line segments of one image.

    centers: (N, 2) float64 px (u, v); directions: (N, 2) unit, angle in
    [0, 180) degrees (v grows downwards); lengths: (N,) px; polarity: (N,)
    int8, the gradient points along +normal (1) or -normal (-1), normal =
    (-dv, du); contrast: (N,) mean gradient magnitude, grey levels per pixel;
    line_id: (N,) int, the Hough (or LSD) line the segment lies on; t: (N,)
    position along that line, px; line_direction: (N, 2) unit direction of
    that whole line's fit (steadier than the local segment's own).
    """

    centers: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    polarity: np.ndarray
    contrast: np.ndarray
    line_id: np.ndarray
    t: np.ndarray
    line_direction: np.ndarray

    def __len__(self) -> int:
        return len(self.centers)

    def select(self, index) -> "Segments2D":
        return Segments2D(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def concatenate(self, other: "Segments2D") -> "Segments2D":
        return Segments2D(*(np.concatenate([getattr(self, f), getattr(other, f)]) for f in self.__dataclass_fields__))

    @property
    def normals(self) -> np.ndarray:
        return np.column_stack([-self.directions[:, 1], self.directions[:, 0]])

    def endpoints(self) -> np.ndarray:
        """(N, 2, 2) endpoints, px."""
        half = (self.lengths / 2)[:, None] * self.directions
        return np.stack([self.centers - half, self.centers + half], axis=1)

    def line_extents(self) -> tuple[np.ndarray, np.ndarray]:
        """(lines,) and (lines,) px: where each line's local segments begin and end along it (``t`` of
        their first and last end; inf and -inf for a line without segments)."""
        n = int(self.line_id.max()) + 1 if len(self) else 0
        return (group_range(self.line_id, n, self.t - self.lengths / 2)[0],
                group_range(self.line_id, n, self.t + self.lengths / 2)[1])


@dataclass(eq=False)
class Gradients:
    """The gradients of one (H, W) uint8 image, computed once and shared by 2D extraction and
    tracking (``Gradients.of``): gx, gy (H, W) float32, grey levels per pixel, Sobel on the image
    blurred by ``blur_sigma`` px. What only extraction needs is computed on first use and kept:
    ``magnitude`` (H, W) float32, the Canny ``edges`` (H, W) uint8 mask (high threshold
    ``gradient_threshold`` grey levels per pixel, low half of it), and the structure tensor smoothed
    by ``tensor_sigma`` px as ``tensor_cos``, ``tensor_sin`` = (Jxx - Jyy, 2 Jxy), whose angle / 2 is
    the normal orientation (steadier than one pixel's gradient on weak edges; see
    ``orientation_at``).

    The magnitude and angle come from numpy, which rounds exactly: OpenCV's SIMD paths
    for them depend on how the arrays happen to be aligned in memory and can differ by
    an ulp between runs, which made extraction differ from run to run."""

    gx: np.ndarray
    gy: np.ndarray
    blur_sigma: float
    gradient_threshold: float
    tensor_sigma: float
    sobel: "tuple[np.ndarray, np.ndarray] | None" = field(default=None, repr=False)   # 8 gx, 8 gy as int16

    @classmethod
    def of(cls, image: np.ndarray, params: "LineParams | None" = None,
           reuse: "Gradients | None" = None, border_distance: "np.ndarray | None" = None) -> "Gradients":
        """Gradients of an (H, W) uint8 image with ``params``' blur, Canny threshold and tensor
        smoothing (``LineParams()`` when None). ``reuse``: gradients already computed for this
        image; returned as they are if made with the same parameters, their gx, gy shared if only
        the threshold or the tensor smoothing differ, ignored if the blur does. ``border_distance``:
        (H, W) uint8, px from pixels that hold no image (``StereoFrame.border_distance``); the
        gradients are zero wherever the blur (3 sigma) and the Sobel (1 px) reach such a pixel, so
        that the border of a rectification's black wedge is no edge for extraction nor tracking."""
        params = params or LineParams()
        if reuse is not None and reuse.blur_sigma == params.blur_sigma:
            if (reuse.gradient_threshold, reuse.tensor_sigma) == (params.gradient_threshold, params.tensor_sigma):
                return reuse
            return cls(reuse.gx, reuse.gy, params.blur_sigma, params.gradient_threshold, params.tensor_sigma,
                       reuse.sobel)
        blurred = cv2.GaussianBlur(image, (0, 0), params.blur_sigma) if params.blur_sigma > 0 else image
        # Sobel of 8-bit grey levels is an integer (|.| <= 1020): int16 holds it for Canny, and
        # float32 / 8 exactly
        dx, dy = cv2.Sobel(blurred, cv2.CV_16S, 1, 0, ksize=3), cv2.Sobel(blurred, cv2.CV_16S, 0, 1, ksize=3)
        if border_distance is not None:
            reached = border_distance <= np.ceil(3 * params.blur_sigma) + 1
            dx[reached], dy[reached] = 0, 0
        gx, gy = dx * np.float32(0.125), dy * np.float32(0.125)
        return cls(gx, gy, params.blur_sigma, params.gradient_threshold, params.tensor_sigma, (dx, dy))

    @cached_property
    def gxy(self) -> np.ndarray:
        """(H, W, 2) float32: gx and gy as the two channels of one image, so that one bilinear
        lookup (``sample``, the tracker's edge search) reads both: the search runs 5 to 12 % faster
        than on the two images apart, more than the copy costs."""
        return cv2.merge([self.gx, self.gy])

    @cached_property
    def magnitude(self) -> np.ndarray:
        # = np.hypot, bit for bit, in one compiled pass at a seventh of its time: gx, gy are integers
        # / 8 under 1024 / 8 (see ``of``), so their squares and sum are exact in float32 and the sqrt
        # rounds once
        return magnitude_image(self.gx, self.gy)

    @cached_property
    def edges(self) -> np.ndarray:
        high = 8.0 * self.gradient_threshold
        dx, dy = self.sobel or ((g * 8).astype(np.int16) for g in (self.gx, self.gy))   # exact integers (``of``)
        return cv2.Canny(dx, dy, high / 2, high, L2gradient=True)

    @cached_property
    def _tensor(self) -> tuple[np.ndarray, np.ndarray]:
        gx, gy = self.gx, self.gy
        jxx, jxy, jyy = (cv2.GaussianBlur(a, (0, 0), self.tensor_sigma) for a in (gx * gx, gx * gy, gy * gy))
        return jxx - jyy, 2 * jxy

    @property
    def tensor_cos(self) -> np.ndarray:
        return self._tensor[0]

    @property
    def tensor_sin(self) -> np.ndarray:
        return self._tensor[1]

    def orientation_at(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Normal angle in [0, pi) of the structure tensor at pixels [rows, cols]."""
        return np.mod(np.arctan2(self.tensor_sin[rows, cols], self.tensor_cos[rows, cols]), 2 * np.pi) / 2


def frame_gradients(frame, params: "LineParams | None" = None) -> tuple[Gradients, Gradients]:
    """(left, right) ``Gradients`` of a rectified stereo frame (anything with ``left`` and ``right``
    (H, W) uint8 images, and optionally ``border_distance`` as ``StereoFrame`` has), for extraction
    and tracking in that frame to share."""
    border = getattr(frame, "border_distance", None) or (None, None)
    return (Gradients.of(frame.left, params, border_distance=border[0]),
            Gradients.of(frame.right, params, border_distance=border[1]))


def parabola_peak(m_minus: np.ndarray, m_center: np.ndarray, m_plus: np.ndarray) -> np.ndarray:
    """Offset (in sample steps, unclipped) of the vertex of the parabola through the samples at
    -1, 0, +1, for any shape of arrays; 0 where the samples do not curve downwards (no maximum).
    Within [-0.5, 0.5] when the centre sample is the largest of the three."""
    curvature = m_minus - 2 * m_center + m_plus
    return np.where(curvature < 0, 0.5 * (m_minus - m_plus) / np.where(curvature < 0, curvature, -1), 0.0)


@dataclass
class StageTimes:
    """Seconds spent per stage, accumulated over calls."""

    seconds: dict = field(default_factory=dict)

    def add(self, stage: str, since: float) -> float:
        now = time.perf_counter()
        self.seconds[stage] = self.seconds.get(stage, 0.0) + now - since
        return now


def sample(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of an (H, W) image at pixel coordinates x, y (any shape), as float32; of an
    (H, W, C) image, shape + (C,)."""
    shape = np.shape(x)
    n = int(np.prod(shape))
    width = 8192  # cv2.remap needs maps narrower than 32767
    rows = max(1, -(-n // width))
    maps = []
    for values in (x, y):
        flat = np.zeros(rows * width, np.float32)
        flat[:n] = np.ravel(values)
        maps.append(flat.reshape(rows, width))
    out = cv2.remap(np.asarray(image, np.float32), maps[0], maps[1], cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    channels = out.shape[2:]
    return out.reshape(-1, *channels)[:n].reshape(*shape, *channels)


@dataclass
class EdgePoints:
    """Edge pixels at sub-pixel positions: xy (M, 2) px; g (M, 2) gradient, grey/px; mag (M,);
    phi (M,) normal angle in [0, pi) from the structure tensor (or None); pixel (M, 2) int (row, column) of
    the Canny pixel each came from."""

    xy: np.ndarray
    g: np.ndarray
    mag: np.ndarray
    phi: np.ndarray
    pixel: np.ndarray


def edge_points(grad: Gradients, with_phi: bool = True) -> EdgePoints:
    """Canny pixels moved along their gradient to the magnitude's parabolic maximum (``phi`` None
    unless ``with_phi``: the structure tensor costs time that only the Hough votes need)."""
    found = cv2.findNonZero(grad.edges)        # row-major, as np.nonzero, three times faster
    pixels = found.reshape(-1, 2).astype(np.int64) if found is not None else np.zeros((0, 2), np.int64)
    rows, cols = pixels[:, 1], pixels[:, 0]
    magnitude = grad.magnitude
    gx, gy, mag = grad.gx[rows, cols], grad.gy[rows, cols], magnitude[rows, cols]
    keep = mag > 0
    rows, cols, gx, gy, mag = rows[keep], cols[keep], gx[keep], gy[keep], mag[keep]
    nx, ny = gx / mag, gy / mag
    m_minus = sample(magnitude, cols - nx, rows - ny)
    m_plus = sample(magnitude, cols + nx, rows + ny)
    offset = np.clip(parabola_peak(m_minus, mag, m_plus), -0.5, 0.5)
    xy = np.column_stack([cols + offset * nx, rows + offset * ny]).astype(np.float64)
    return EdgePoints(xy, np.column_stack([gx, gy]).astype(np.float64), mag.astype(np.float64),
                      grad.orientation_at(rows, cols).astype(np.float64) if with_phi else None,
                      np.column_stack([rows, cols]))


def hough_assign(points: EdgePoints, shape: tuple[int, int], params: LineParams) -> np.ndarray:
    """(M,) Hough line label of every edge point (-1: on no line).

    Peaks are 3x3 local maxima of the lightly smoothed accumulator, refined to
    sub-bin precision by the centroid of their neighbourhood. A point's
    candidates are the peaks near the cells its own votes fell in; it joins the
    candidate line it lies closest to (within 2.5 px). A strong line spreads
    over its neighbourhood in the accumulator and can hide a weak line a few
    pixels away, so this runs ``hough_passes`` times, each over the votes of
    the points no line has taken yet.
    """
    h, w = shape
    step = np.radians(params.angle_step_deg)
    n_phi = int(round(np.pi / step))
    half_window = max(1, int(round(params.vote_window_deg / params.angle_step_deg)))
    radius = int(np.ceil(np.hypot(w, h) / 2)) + 4
    n_rho = 2 * radius + 1
    x = points.xy[:, 0] - (w - 1) / 2.0
    y = points.xy[:, 1] - (h - 1) / 2.0
    phi_own = points.phi / step  # in bins
    k = np.arange(-half_window, half_window + 1)
    bins = np.round(phi_own)[:, None] + k  # (M, 2w+1)
    kernel = np.clip(1.0 - np.abs(bins - phi_own[:, None]) / (half_window + 1), 0.0, None)
    bins = np.mod(bins, n_phi).astype(np.int64)
    table = np.arange(n_phi) * step
    rho = np.rint(x[:, None] * np.cos(table)[bins] + y[:, None] * np.sin(table)[bins]).astype(np.int64) + radius
    flat = bins * n_rho + rho
    votes = kernel * points.mag[:, None]
    labels = np.full(len(x), -1)
    n_labels = 0
    for _ in range(params.hough_passes):
        free = labels < 0
        if free.sum() < params.min_line_support_px:
            break
        acc = np.bincount(flat[free].ravel(), weights=votes[free].ravel(),
                          minlength=n_phi * n_rho).reshape(n_phi, n_rho).astype(np.float32)
        line_phi, line_rho, candidates = _hough_peaks(acc, flat[free], params, step, radius)
        if len(line_phi) == 0:
            break
        c = np.maximum(candidates, 0)
        xf, yf = x[free][:, None], y[free][:, None]
        distance = np.abs(xf * np.cos(line_phi)[c] + yf * np.sin(line_phi)[c] - line_rho[c])
        distance = np.where(candidates >= 0, distance, np.inf)
        choice = np.argmin(distance, axis=1)
        rows = np.arange(len(choice))
        chosen = np.where(distance[rows, choice] <= 2.5, candidates[rows, choice] + n_labels, -1)
        labels[free] = chosen
        n_labels += len(line_phi)
    return labels


def _hough_peaks(acc: np.ndarray, flat: np.ndarray, params: LineParams, step: float, radius: int):
    """Peaks of an accumulator: (phi (K,) radians, rho (K,) px) refined to sub-bin precision, and
    for each vote in ``flat`` (M, 2w+1) the index of the peak whose neighbourhood it fell in, or -1."""
    n_phi, n_rho = acc.shape
    pad = 2  # phi wraps: phi + 180 is the same line with rho mirrored
    wrapped = np.vstack([acc[-pad:, ::-1], acc, acc[:pad, ::-1]])
    smooth = cv2.GaussianBlur(wrapped, (3, 3), 0.7)
    is_peak = smooth == cv2.dilate(smooth, np.ones((3, 3), np.uint8))
    is_peak[:pad] = is_peak[-pad:] = False
    threshold = params.min_line_support_px * params.gradient_threshold
    peak_phi, peak_rho = np.nonzero(is_peak & (smooth >= threshold))
    order = np.argsort(-smooth[peak_phi, peak_rho])[: params.max_lines]
    peak_phi, peak_rho = peak_phi[order], peak_rho[order]
    n_peaks = len(peak_phi)
    if n_peaks == 0:
        return np.zeros(0), np.zeros(0), np.full(flat.shape, -1)
    # sub-bin position: centroid of the 3x3 neighbourhood (in the padded, continuous array)
    dphi, drho = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2), indexing="ij")
    rho_idx = np.clip(peak_rho[:, None] + drho.ravel(), 0, n_rho - 1)
    weights = smooth[peak_phi[:, None] + dphi.ravel(), rho_idx]
    total = weights.sum(axis=1)
    line_phi = (peak_phi - pad + (weights * dphi.ravel()).sum(axis=1) / total) * step
    line_rho = (peak_rho + (weights * drho.ravel()).sum(axis=1) / total) - radius
    # label map: cells near a peak name it (the stronger peak where two are near)
    cell_phi = peak_phi[:, None] - pad + np.repeat(np.arange(-1, 2), 5)[None, :]
    cell_rho = peak_rho[:, None] + np.tile(np.arange(-2, 3), 3)[None, :]
    wraps = (cell_phi < 0) | (cell_phi >= n_phi)
    cell_rho = np.where(wraps, n_rho - 1 - cell_rho, cell_rho)
    cell_phi = np.mod(cell_phi, n_phi)
    inside = (cell_rho >= 0) & (cell_rho < n_rho)
    rank = np.broadcast_to((n_peaks - np.arange(n_peaks))[:, None], cell_phi.shape)
    best = np.zeros(n_phi * n_rho, np.int64)
    np.maximum.at(best, (cell_phi * n_rho + cell_rho)[inside], rank[inside])
    return line_phi, line_rho, np.where(best[flat] > 0, n_peaks - best[flat], -1)


def _weighted_line_fit(index: np.ndarray, n_groups: int, xy: np.ndarray, w: np.ndarray):
    """Per group: weight sum, centroid (G, 2), unit direction (G, 2) of a weighted TLS line fit
    (``group_kernel.group_line_fit``)."""
    return group_line_fit(np.ascontiguousarray(index, np.int64), int(n_groups), np.asarray(xy, np.float64),
                          np.ascontiguousarray(w, np.float64))


def directed_line_fit(index: np.ndarray, n_groups: int, xy: np.ndarray, w: np.ndarray,
                      direction_weight: np.ndarray | None):
    """``_weighted_line_fit`` by ``w``, its direction fitted by ``direction_weight`` instead (None: by
    ``w``): the centroid is every pixel's, the direction leans less on the pixels a caller distrusts
    (``edge_chains.end_tapered_weights``)."""
    sw, center, direction = _weighted_line_fit(index, n_groups, xy, w)
    if direction_weight is not None:
        direction = _weighted_line_fit(index, n_groups, xy, direction_weight)[2]
    return sw, center, direction


def pieces_along(middle: np.ndarray, direction: np.ndarray, reach: np.ndarray, pieces: "Segments2D",
                 tree=None) -> tuple[np.ndarray, ...]:
    """Pairs (k, m) of segments (``middle`` (K, 2) px, unit ``direction`` (K, 2)) and the ``pieces``
    whose centre lies within ``reach`` (K,) px of the middle, with each piece's place on its segment:
    ``along`` (signed) and ``across`` px and the |cos| of their angle (``cosine``); what counts as
    lying on the segment is the caller's test. One KD-tree search per class of reach, so that a few
    long segments do not widen every search. ``tree``: a cKDTree of the pieces' centres, if built."""
    tree = tree if tree is not None else cKDTree(pieces.centers)
    k, m = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for shortest, longest in ((0.0, 12.0), (12.0, 32.0), (32.0, np.inf)):
        group = np.flatnonzero((reach >= shortest) & (reach < longest))
        if len(group):
            pairs = cKDTree(middle[group]).sparse_distance_matrix(tree, reach[group].max(), output_type="ndarray")
            k.append(group[pairs["i"]])
            m.append(pairs["j"].astype(np.int64))
    k, m = np.concatenate(k), np.concatenate(m)
    rel = pieces.centers[m] - middle[k]
    along = np.sum(rel * direction[k], axis=1)
    across = np.abs(rel[:, 0] * direction[k, 1] - rel[:, 1] * direction[k, 0])
    return k, m, along, across, np.abs(np.sum(pieces.directions[m] * direction[k], axis=1))


def dot2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of (N, 2) arrays: ``np.sum(a * b, axis=1)`` bit for bit, without its
    (N, 2) temporary and short-axis reduction (several times faster)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]


def _canonical(directions: np.ndarray) -> np.ndarray:
    """Directions with angle in [0, 180): dv > 0, or dv == 0 and du > 0."""
    flip = (directions[:, 1] < 0) | ((directions[:, 1] == 0) & (directions[:, 0] < 0))
    return np.where(flip[:, None], -directions, directions)


def local_segments(points: EdgePoints, labels: np.ndarray, params: LineParams,
                   adapt_length: bool = False, line_fit: bool = False,
                   min_support_px: float = 0.0, corner_min_support_px: float | None = None,
                   direction_weight: np.ndarray | None = None) -> Segments2D:
    """Cut every labelled line into local segments (see the module docstring).

    Along a line, consecutive supporting pixels (gaps up to ``max_gap_px``,
    same polarity) form runs. A run at least ``min_fill * L`` long, spanning
    ``min_support_px`` of pixels (before the end extension) and filled
    to ``min_fill`` gives ``ceil(R / L)`` pieces of length L spread evenly from
    its first to its last pixel (overlapping a little where R is not a
    multiple of L), so that an edge is covered to its ends; each piece is
    fitted to the pixels nearest its centre. ``adapt_length``: a run shorter than L gives one piece
    of the run's own length, longer runs are tiled by ``ceil(R / L)`` equal pieces (else every
    piece is L long). ``line_fit``: a piece lies on its line's fit (direction the line's, centre
    the line's point at the piece's mean position along it) instead of its own pixels' fit; for
    labels that are straight by construction, whose whole fit is steadier than a few pixels'.
    ``corner_min_support_px``: a run that ``_complete_junctions`` grows to a corner at both ends
    needs only this span of pixels, if less than ``min_support_px`` (a run already reaching its
    corner is not grown, and needs ``min_support_px``). ``direction_weight``: (M,) the points'
    weights in their line's direction (its centroid and everything else weigh by magnitude), None:
    their magnitudes.
    """
    on_line = np.flatnonzero(labels >= 0)
    if len(on_line) == 0:
        return _empty()
    xy, g, mag, labels = points.xy[on_line], points.g[on_line], points.mag[on_line], labels[on_line].astype(np.int64)
    n_lines = int(labels.max()) + 1
    _, line_center, line_dir = directed_line_fit(labels, n_lines, xy, mag,
                                                 None if direction_weight is None else direction_weight[on_line])
    line_normal = np.column_stack([-line_dir[:, 1], line_dir[:, 0]])
    t, across, polarity = line_coordinates(np.ascontiguousarray(xy, np.float64), np.ascontiguousarray(g, np.float64),
                                           labels, line_center, line_dir)
    keep = np.flatnonzero(np.abs(across) <= params.max_line_distance_px)
    order = keep[line_order(labels[keep], polarity[keep], t[keep])]   # = np.lexsort((t, polarity, labels)) of those kept
    # runs of supporting pixels
    L = params.segment_length_px
    run, t_lo, t_hi, run_line, count_run = supporting_runs(order, labels, polarity, t, float(params.max_gap_px))
    fill = count_run / ((t_hi - t_lo + 1.0) * np.max(np.abs(line_dir[run_line]), axis=1))
    support = t_hi - t_lo + 1.0
    # a run without the fill or the support gives no piece whatever it grows: its growth is not needed
    least = min_support_px if corner_min_support_px is None else min(min_support_px, corner_min_support_px)
    needed = (fill >= params.min_fill) & (support >= least)
    grown_lo, grown_hi = _complete_junctions(t_lo, t_hi, line_center[run_line], line_dir[run_line], run_line, needed,
                                             params)
    if least < min_support_px:    # the shorter runs count only between two corners
        needed &= (support >= min_support_px) | ((grown_lo < t_lo) & (grown_hi > t_hi))
    t_lo, t_hi = grown_lo, grown_hi
    run_length = t_hi - t_lo + 1.0
    # Canny and the vote lose a pixel or two where edges meet: let the pieces reach past the run's ends
    t_lo, run_length = t_lo - params.end_extension_px, run_length + 2 * params.end_extension_px
    long_enough = (run_length >= params.min_fill * L) & needed
    pieces = np.where(long_enough, np.ceil(run_length / L), 0).astype(np.int64)
    # piece centres evenly from the run's first to its last pixel (overlapping slightly when needed)
    if adapt_length:   # pieces of equal length tiling the run
        piece_length = run_length / np.maximum(pieces, 1)
        first_center = t_lo + piece_length / 2 - 0.5
        spacing = piece_length
    else:
        first_center = t_lo + np.minimum(L, run_length) / 2 - 0.5
        spacing = np.where(pieces > 1, (run_length - L) / np.maximum(pieces - 1, 1), 0.0)
    group, sw, swt, count, group_run, first = piece_groups(order, run, t, mag, first_center, spacing, pieces)
    n_groups = len(sw)
    if n_groups == 0:
        return _empty()
    group_line, group_polarity = labels[first], polarity[first]
    if line_fit:
        t_mean = swt / np.maximum(sw, 1e-12)
        directions = line_dir[group_line]
        centers = line_center[group_line] + t_mean[:, None] * directions
    else:
        pieced = group >= 0
        _, centers, directions = _weighted_line_fit(group[pieced], n_groups, xy[order[pieced]], mag[order[pieced]])
    agree = np.abs(dot2(directions, line_dir[group_line])) >= np.cos(
        np.radians(2 * params.vote_window_deg))
    ok = (count >= 3) & agree
    directions = _canonical(directions[ok])
    own_normal = np.column_stack([-directions[:, 1], directions[:, 0]])
    sign = np.sign(dot2(own_normal, line_normal[group_line[ok]]))
    seg_t = dot2(centers[ok] - line_center[group_line[ok]], line_dir[group_line[ok]])
    lengths = piece_length[group_run[ok]] if adapt_length else np.full(int(ok.sum()), L)
    return Segments2D(centers=centers[ok], directions=directions, lengths=lengths,
                      polarity=(group_polarity[ok] * sign).astype(np.int8), contrast=(sw / np.maximum(count, 1))[ok],
                      line_id=group_line[ok], t=seg_t, line_direction=_canonical(line_dir[group_line[ok]]))


def refine_on_gradient(segments: Segments2D, magnitude: np.ndarray, profiles: int = 13,
                       reach: int = 2, max_turn_deg: float = 3.0) -> Segments2D:
    """Sub-pixel position and orientation of local segments from the gradient itself.

    Along each segment, ``profiles`` cuts across it (along its own normal, so
    every cut of one segment looks the same way) sample the gradient
    magnitude at whole-pixel offsets within ``reach``; a parabola through the
    strongest sample and its neighbours places the edge in each cut, and a
    weighted total-least-squares line through those points is the refined
    segment. Per-pixel edge points carry a staircase bias on slanted edges
    that this avoids. A segment that would move more than 1 px or turn more than ``max_turn_deg``
    keeps its place.
    """
    n = len(segments)
    if n == 0:
        return segments
    normals = segments.normals
    t = np.linspace(-0.4, 0.4, profiles)[None, :] * segments.lengths[:, None]                 # (N, P)
    h = np.arange(-reach, reach + 1, dtype=float)                                              # (H,)
    base, x, y = cut_grid(*(np.ascontiguousarray(a, np.float64) for a in (segments.centers, segments.directions,
                                                                          normals, t)), h)     # (N, P, 2), (N, P, H)
    peaks, weights = cut_peaks(sample(magnitude, x, y), base, np.ascontiguousarray(normals, np.float64), h,
                               float(reach))
    group = np.repeat(np.arange(n), profiles)
    _, centers, directions = _weighted_line_fit(group, n, peaks.reshape(-1, 2), weights.ravel())
    directions = np.where((dot2(directions, segments.directions) < 0)[:, None], -directions, directions)
    refined = Segments2D(centers, directions, segments.lengths, segments.polarity, segments.contrast,
                         segments.line_id, segments.t, segments.line_direction)
    # a cut that lost the edge (corner, clutter) shows as a large change: keep the original then
    moved = (np.abs(dot2(centers - segments.centers, normals)) > 1.0) | \
        (np.abs(dot2(directions, segments.directions)) < np.cos(np.radians(max_turn_deg)))
    return Segments2D(*(np.where(moved.reshape((-1,) + (1,) * (a.ndim - 1)), a, b)
                        for a, b in ((getattr(segments, f), getattr(refined, f))
                                     for f in Segments2D.__dataclass_fields__)))


JUNCTION_MIN_DEG = 20.0     # lines closer in direction than this do not meet at a corner


def _complete_junctions(t_lo, t_hi, centers, directions, line, needed, params: LineParams):
    """Extend runs whose ends meet another line's run end at a corner.

    Near a junction the gradient belongs to two edges, so Canny and the votes
    lose the last pixels of each. Where the ends of two runs on different lines, more than
    ``JUNCTION_MIN_DEG`` apart in direction, lie within ``junction_radius_px`` of the lines'
    intersection, both runs are extended to it. Returns new (t_lo, t_hi), exact for the ``needed``
    (N,) runs (``pair_kernel.junction_growth``).
    """
    radius = params.junction_radius_px
    ends = np.concatenate([centers + t_lo[:, None] * directions, centers + t_hi[:, None] * directions])
    n = len(t_lo)
    outward = np.concatenate([-directions, directions])
    contiguous = np.ascontiguousarray
    grow = junction_growth(contiguous(ends, np.float64), contiguous(outward, np.float64), contiguous(centers, np.float64),
                           contiguous(directions, np.float64), contiguous(line, np.int64), contiguous(needed, np.bool_),
                           float(2 * radius), float(radius),
                           float(np.sin(np.radians(JUNCTION_MIN_DEG))), JUNCTION_MIN_DEG)
    return t_lo - grow[:n], t_hi + grow[n:]


def _empty() -> Segments2D:
    return Segments2D(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int8), np.zeros(0),
                      np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2)))


def detection_start(image: np.ndarray, params: "LineParams", grad: "Gradients | None",
                    times: "StageTimes | None") -> tuple:
    """What every detector does first: the image's gradients (computed unless given) timed as the
    'gradients' stage; returns (gradients, times, the clock after them)."""
    times = times or StageTimes()
    t0 = time.perf_counter()
    grad = grad or Gradients.of(image, params)
    return grad, times, times.add("gradients", t0)


def detect_hough(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
                 times: StageTimes | None = None) -> Segments2D:
    """Local segments of an (H, W) uint8 image by the orientation-sensitive Hough transform."""
    grad, times, t0 = detection_start(image, params, grad, times)
    points = edge_points(grad)
    labels = hough_assign(points, image.shape, params)
    t0 = times.add("lines", t0)
    segments = refine_on_gradient(local_segments(points, labels, params), grad.magnitude)
    times.add("local segments", t0)
    return segments


def pieces_on_lines(a: np.ndarray, b: np.ndarray, grad: Gradients, params: LineParams) -> Segments2D:
    """Local segments along detected line segments from ``a`` to ``b`` ((K, 2) px each).

    A line of length R at least ``min_fill * segment_length_px`` (L) is cut into ``ceil(R / L)``
    equal pieces that tile it end to end, so a piece's length adapts to its edge (between L / 2 and
    L; a line shorter than L is one piece of its own length). ``line_id`` is the line's index, ``t``
    the piece centre's position from the line's midpoint. Polarity and contrast are the mean gradient
    along the normal at five points of the piece; pieces weaker than half ``gradient_threshold`` are
    dropped, the rest refined on the gradient (``refine_on_gradient``)."""
    L = params.segment_length_px
    length = np.linalg.norm(b - a, axis=1)
    pieces = np.where(length >= params.min_fill * L, np.ceil(length / L), 0).astype(np.int64)
    line = np.repeat(np.arange(len(a)), pieces)
    if len(line) == 0:
        return _empty()
    first = np.cumsum(pieces) - pieces
    index_in_line = np.arange(len(line)) - np.repeat(first, pieces)
    piece_length = (length / np.maximum(pieces, 1))[line]
    direction = (b - a) / np.maximum(length, 1e-9)[:, None]
    t = (index_in_line + 0.5) * piece_length - length[line] / 2
    centers = (a + b)[line] / 2 + t[:, None] * direction[line]
    directions = _canonical(direction[line])
    normals = np.column_stack([-directions[:, 1], directions[:, 0]])
    s = np.linspace(-0.4, 0.4, 5)[None, :] * piece_length[:, None]
    x = centers[:, 0:1] + s * directions[:, 0:1]
    y = centers[:, 1:2] + s * directions[:, 1:2]
    g = sample(grad.gxy, x, y)
    along_normal = (g[..., 0] * normals[:, 0:1] + g[..., 1] * normals[:, 1:2]).mean(axis=1)
    line_direction = _canonical(direction)[line]
    # t along the canonical line direction
    t = np.where(dot2(line_direction, direction[line]) < 0, -t, t)
    segments = Segments2D(centers, directions, piece_length, np.where(along_normal >= 0, 1, -1).astype(np.int8),
                          np.abs(along_normal).astype(np.float64), line, t, line_direction)
    return refine_on_gradient(segments.select(segments.contrast >= params.gradient_threshold / 2), grad.magnitude)


def _detect_with(find_lines, image: np.ndarray, params: LineParams, grad: Gradients | None,
                 times: StageTimes | None) -> Segments2D:
    """Local segments of the (K, 4) line segments (u0, v0, u1, v1 px) that ``find_lines(image,
    params)`` returns, with the same stage breakdown as the Hough detector."""
    grad, times, t0 = detection_start(image, params, grad, times)
    ends = np.asarray(find_lines(image, params), np.float64).reshape(-1, 4)
    t0 = times.add("lines", t0)  # the line-finding stage (whatever the detector), for comparable breakdowns
    segments = pieces_on_lines(ends[:, :2], ends[:, 2:], grad, params)
    times.add("local segments", t0)
    return segments


_LSD = None


def _lsd_lines(image: np.ndarray, params: LineParams) -> np.ndarray:
    global _LSD
    if _LSD is None:
        _LSD = cv2.createLineSegmentDetector(cv2.LSD_REFINE_STD)
    found = _LSD.detect(image)[0]
    return np.zeros((0, 4)) if found is None else found


def detect_lsd(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
               times: StageTimes | None = None) -> Segments2D:
    """Local segments from OpenCV's line segment detector (``pieces_on_lines``)."""
    return _detect_with(_lsd_lines, image, params, grad, times)


def _ximgproc():
    """opencv-contrib's ximgproc module; InputError if the installed OpenCV lacks it."""
    if not hasattr(cv2, "ximgproc"):
        raise InputError("the fld and ed detectors need opencv-contrib-python-headless (cv2.ximgproc)")
    return cv2.ximgproc


OPENCV_LINE_BLUR = 1.0   # px: the blur before fld's and ed's own line finding, as they were measured


def _fld_lines(image: np.ndarray, params: LineParams) -> np.ndarray:
    high = 8.0 * params.gradient_threshold  # Canny on 3x3 Sobel, as Gradients.edges
    fld = _ximgproc().createFastLineDetector(int(np.ceil(params.min_fill * params.segment_length_px)), 1.414,
                                              high / 2, high, 3, False)
    found = fld.detect(cv2.GaussianBlur(image, (0, 0), OPENCV_LINE_BLUR))
    return np.zeros((0, 4)) if found is None else found


def detect_fld(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
               times: StageTimes | None = None) -> Segments2D:
    """Local segments from opencv-contrib's FastLineDetector (``pieces_on_lines``)."""
    return _detect_with(_fld_lines, image, params, grad, times)


def _ed_lines(image: np.ndarray, params: LineParams) -> np.ndarray:
    ed = _ximgproc().createEdgeDrawing()
    p = _ximgproc().EdgeDrawing.Params()
    p.MinLineLength = int(np.ceil(params.min_fill * params.segment_length_px))
    p.MinPathLength = p.MinLineLength
    p.Sigma = OPENCV_LINE_BLUR
    p.GradientThresholdValue = int(round(8 * params.gradient_threshold))
    p.AnchorThresholdValue = int(round(4 * params.gradient_threshold))
    p.NFAValidation = False
    ed.setParams(p)
    ed.detectEdges(image)
    found = ed.detectLines()
    return np.zeros((0, 4)) if found is None else found


def detect_ed(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
              times: StageTimes | None = None) -> Segments2D:
    """Local segments from opencv-contrib's EdgeDrawing lines (``pieces_on_lines``)."""
    return _detect_with(_ed_lines, image, params, grad, times)


def detect_chains(image: np.ndarray, params: LineParams, grad: Gradients | None = None,
                  times: StageTimes | None = None) -> Segments2D:
    """Local segments from straight edge chains: ``edge_chains.detect_chains`` (that module builds
    on this one, so it is imported here on first use)."""
    from .edge_chains import detect_chains as detect

    return detect(image, params, grad, times)



DETECTORS = {"hough": detect_hough, "lsd": detect_lsd, "fld": detect_fld, "ed": detect_ed, "chains": detect_chains}
