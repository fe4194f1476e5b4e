"""A transform tree with time interpolation (the ROS tf semantics of formats.md).

Each parent/child pair holds its samples sorted by time. A pair with a single
sample in the whole recording, or one marked static (``/tf_static``), holds at
all times. A lookup composes the edges on the path between two frames, each
interpolated at the query time (linear translation, slerp rotation). A query
outside an edge's sample range by more than the tolerance is refused with the
reason, never extrapolated.

Defined behaviour for odd input:
- Samples may arrive in any order; they are sorted by time. Of several samples
  of one pair at the same time the last one received is kept.
- A sample whose quaternion is not finite or zero, or whose translation is not
  finite or farther than ``MAX_TRANSLATION_M``, is invalid (``sample_problem``
  says why): it is kept, so that a lookup needing it fails with
  ``PoseUnavailable`` instead of silently bridging it. Quaternions are
  normalised without overflow (any finite non-zero size is fine).
- Times are integer nanoseconds anywhere in the int64 range (negative too).
- A query between two samples further apart than ``GAP_FACTOR`` times the pair's median sample
  spacing (and ``MIN_GAP_NS``) is refused: the transform stream had a gap there, and interpolating
  across it (a robot turning the object 10 degrees a frame, /tf silent for 1.2 s) gave a model of
  precision 0.70 instead of 0.98 without a word.
- A cycle, or a frame with two parents, is not an error: ``path`` takes the
  shortest chain of edges (the first found on ties); ``ambiguous_frames`` names
  the frames with more than one parent so the reader can warn.
"""

from __future__ import annotations

import re
from collections import defaultdict, deque
from dataclasses import dataclass, field

import numpy as np

from ..errors import PoseUnavailable
from ..geometry import interpolate, invert, transform_from_quat

MAX_TRANSLATION_M = 1e4
# a frame's time outside an edge's samples: the message, and its pattern for grouping such reasons by time
OUTSIDE_SAMPLES = "time {:.3f} s is outside the transform samples [{:.3f}, {:.3f}] s"
OUTSIDE_SAMPLES_PATTERN = re.compile(r"time (-?\d+(?:\.\d+)?) s is outside the transform samples "
                                     r"\[(-?[\d.]+), (-?[\d.]+)\] s")
GAP_FACTOR = 4.0           # samples further apart than this many median spacings: a gap, not interpolated
MIN_GAP_NS = 100_000_000   # ... and at least this far apart (a slow /tf of a slow robot is no gap)


def sample_problem(translation, quat_xyzw) -> str | None:
    """Why a transform sample (translation metres, quaternion xyzw) is invalid, or None."""
    t = np.asarray(translation, float)
    q = np.asarray(quat_xyzw, float)
    if not np.isfinite(q).all():
        return "invalid quaternion (not finite)"
    if not q.any():
        return "invalid quaternion (zero)"
    if not np.isfinite(t).all():
        return "invalid translation (not finite)"
    if np.abs(t).max() > MAX_TRANSLATION_M:
        return f"invalid translation (beyond {MAX_TRANSLATION_M:g} m)"
    return None


def normalised_quats(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions of finite non-zero ``q: (N, 4)``; others as given.

    ``q / |q|`` where the norm is a normal float; rows whose norm overflows or
    underflows are scaled by their largest part first.
    """
    with np.errstate(invalid="ignore", over="ignore", under="ignore"):
        scale = np.abs(q).max(axis=1, keepdims=True)
        ok = np.isfinite(scale) & (scale > 0)
        norm = np.linalg.norm(q, axis=1, keepdims=True)
        plain = np.isfinite(norm) & (norm >= np.finfo(float).tiny)
        scaled = q / np.where(ok, scale, 1.0)
        scaled = scaled / np.where(ok, np.linalg.norm(scaled, axis=1, keepdims=True), 1.0)
        return np.where(plain, q / np.where(plain, norm, 1.0), np.where(ok, scaled, q))


@dataclass
class TransformSamples:
    """Samples of ``T_parent_child`` over time.

    times_ns: (N,) int64, increasing; translations: (N, 3) metres; quats_xyzw:
    (N, 4), unit where valid; valid: (N,) bool, False where ``sample_problem``
    finds one (kept so that a lookup that needs it fails loudly instead of
    silently bridging it).
    """

    parent: str
    child: str
    times_ns: np.ndarray
    translations: np.ndarray
    quats_xyzw: np.ndarray
    valid: np.ndarray
    static: bool

    @property
    def spacing_ns(self) -> float:
        """The median time between consecutive samples, ns (inf with fewer than two)."""
        if "_spacing" not in self.__dict__:
            steps = np.diff(self.times_ns)
            self.__dict__["_spacing"] = float(np.median(steps)) if len(steps) else float("inf")
        return self.__dict__["_spacing"]

    @property
    def gap_ns(self) -> float:
        """Samples further apart than this are a gap in the stream (module docstring)."""
        return max(GAP_FACTOR * self.spacing_ns, MIN_GAP_NS)

    def at(self, t_ns: int, tolerance_ns: int) -> np.ndarray:
        """``T_parent_child`` at ``t_ns``; raises ``PoseUnavailable``."""
        if self.static:
            i = int(np.flatnonzero(self.valid)[-1]) if self.valid.any() else -1
            if i < 0:
                raise PoseUnavailable(f"{self.parent} -> {self.child}: the static transform has an "
                                      f"{self._problem(-1)}")
            return self._transform(i)
        t = self.times_ns
        t_ns = int(t_ns)
        if t_ns < int(t[0]) - tolerance_ns or t_ns > int(t[-1]) + tolerance_ns:
            raise PoseUnavailable(f"{self.parent} -> {self.child}: "
                                  + OUTSIDE_SAMPLES.format(t_ns * 1e-9, t[0] * 1e-9, t[-1] * 1e-9))
        hi = int(np.searchsorted(t, t_ns, side="left"))
        if hi < len(t) and t[hi] == t_ns:
            lo = hi
        else:
            lo, hi = max(hi - 1, 0), min(hi, len(t) - 1)
        if int(t[hi]) - int(t[lo]) > self.gap_ns:
            raise PoseUnavailable(
                f"{self.parent} -> {self.child}: time {t_ns * 1e-9:.3f} s falls in a gap of the transform samples "
                f"([{t[lo] * 1e-9:.3f}, {t[hi] * 1e-9:.3f}] s, their median spacing {self.spacing_ns * 1e-9:.3f} s)")
        for i in {lo, hi}:
            if not self.valid[i]:
                raise PoseUnavailable(f"{self.parent} -> {self.child}: the sample at {t[i] * 1e-9:.3f} s has an "
                                      f"{self._problem(i)}")
        if lo == hi:
            return self._transform(lo)
        s = (int(t_ns) - int(t[lo])) / (int(t[hi]) - int(t[lo]))
        return interpolate(self._transform(lo), self._transform(hi), float(s))

    def _problem(self, i: int) -> str:
        return sample_problem(self.translations[i], self.quats_xyzw[i]) or "invalid sample"

    def _transform(self, i: int) -> np.ndarray:
        return transform_from_quat(self.translations[i], self.quats_xyzw[i])


def frame_name(name: str) -> str:
    """A frame's name as tf2 keys it: without a leading '/' (ROS 1's tf wrote '/base_link'; tf2 strips it, so
    '/camera_left' and 'camera_left' are one frame)."""
    return name[1:] if isinstance(name, str) and name.startswith("/") else name


@dataclass
class TransformTree:
    """Collects transform samples, then answers ``lookup(target, source, t)``."""

    _raw: dict = field(default_factory=lambda: defaultdict(list))
    _static_pairs: set = field(default_factory=set)
    edges: dict = field(default_factory=dict)

    def add(self, parent: str, child: str, t_ns: int, translation, quat_xyzw, static: bool = False) -> None:
        """Record one sample of ``T_parent_child`` (translation metres, quaternion xyzw, time int ns);
        frame names as ``frame_name`` makes them."""
        parent, child = frame_name(parent), frame_name(child)
        self._raw[(parent, child)].append((int(t_ns), *translation, *quat_xyzw))
        if static:
            self._static_pairs.add((parent, child))
        self.edges.pop((parent, child), None)

    def _edge(self, key) -> TransformSamples:
        if key not in self.edges:
            latest = {r[0]: r for r in self._raw[key]}  # the last sample received at each time
            samples = [latest[t] for t in sorted(latest)]
            times = np.array([r[0] for r in samples], np.int64)
            rows = np.array([r[1:] for r in samples], dtype=float).reshape(-1, 7)
            valid = np.array([sample_problem(r[:3], r[3:]) is None for r in rows], bool)
            q = normalised_quats(rows[:, 3:7])
            self.edges[key] = TransformSamples(
                parent=key[0], child=key[1], times_ns=times, translations=rows[:, :3], quats_xyzw=q, valid=valid,
                static=key in self._static_pairs or len(rows) == 1)
        return self.edges[key]

    @property
    def frames(self) -> set[str]:
        return {f for key in self._raw for f in key}

    def ambiguous_frames(self) -> dict[str, list[str]]:
        """Frames with more than one parent: {child: sorted parents}."""
        parents = defaultdict(set)
        for parent, child in self._raw:
            parents[child].add(parent)
        return {c: sorted(p) for c, p in sorted(parents.items()) if len(p) > 1}

    def path(self, target: str, source: str) -> list[tuple[tuple[str, str], bool]] | None:
        """Edges from ``target`` to ``source`` as ((parent, child), forward) or None if unconnected.

        ``forward`` means the edge is traversed parent -> child, i.e. it
        contributes ``T_parent_child`` to ``T_target_source``.
        """
        target, source = frame_name(target), frame_name(source)
        neighbours = defaultdict(list)
        for parent, child in self._raw:
            neighbours[parent].append((child, (parent, child), True))
            neighbours[child].append((parent, (parent, child), False))
        previous = {target: None}
        queue = deque([target])
        while queue:
            frame = queue.popleft()
            if frame == source:
                break
            for nxt, key, forward in neighbours[frame]:
                if nxt not in previous:
                    previous[nxt] = (frame, key, forward)
                    queue.append(nxt)
        if source not in previous:
            return None
        steps, frame = [], source
        while previous[frame] is not None:
            frame, key, forward = previous[frame]
            steps.append((key, forward))
        return steps[::-1]

    def lookup(self, target: str, source: str, t_ns: int, tolerance_ns: int = 1_000_000) -> np.ndarray:
        """``T_target_source`` at ``t_ns``; raises ``PoseUnavailable`` with the reason."""
        steps = self.path(target, source)
        if steps is None:
            raise PoseUnavailable(f"no path from {target} to {source} in the transform tree")
        T = np.eye(4)
        for key, forward in steps:
            T_parent_child = self._edge(key).at(t_ns, tolerance_ns)
            T = T @ (T_parent_child if forward else invert(T_parent_child))
        return T

    def time_range(self, target: str, source: str) -> tuple[int, int] | None:
        """Intersection of the moving edges' sample ranges on the path, or None if all static."""
        steps = self.path(target, source) or []
        lo, hi = None, None
        for key, _ in steps:
            edge = self._edge(key)
            if not edge.static:
                lo = edge.times_ns[0] if lo is None else max(lo, edge.times_ns[0])
                hi = edge.times_ns[-1] if hi is None else min(hi, edge.times_ns[-1])
        return None if lo is None else (int(lo), int(hi))
