"""Curves over the frames of a run, as a paper shows them: the model's counts (size, accepted,
confirmed, new, pruned) and, against a truth, precision, completeness and background; or the
single-frame figures of a frames file. Drawn with matplotlib (Agg, no display) into a PNG."""

from __future__ import annotations

import math

COUNTS = ("size", "accepted", "confirmed", "new", "pruned")
SCORES = ("precision", "completeness", "background", "accuracy_near_object")


def _series(rows, key):
    xs = [r.get("frame_index", i) for i, r in enumerate(rows)]
    ys = [r.get(key) for r in rows]
    return [x for x, y in zip(xs, ys) if isinstance(y, (int, float)) and math.isfinite(y)], \
        [y for y in ys if isinstance(y, (int, float)) and math.isfinite(y)]


def plot_frames(target, rows, title: str) -> None:
    """A PNG of ``rows`` (one dict per frame, ``frame_index`` and any of COUNTS and SCORES) to a path
    or an open binary file: counts on the left axis panel, scores (0..1) on the right one."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    counts = [k for k in COUNTS if any(k in r for r in rows)]
    scores = [k for k in SCORES if any(isinstance(r.get(k), float) for r in rows)]
    panels = [p for p in (counts, scores) if p]
    figure = Figure(figsize=(6.4 * len(panels), 4.0), dpi=100, layout="constrained")
    for i, keys in enumerate(panels):
        axes = figure.add_subplot(1, len(panels), i + 1)
        for key in keys:
            xs, ys = _series(rows, key)
            axes.plot(xs, ys, marker="." if len(xs) < 60 else None, label=key.replace("_", " "))
        axes.set_xlabel("frame")
        axes.set_ylabel("segments" if keys is counts else "fraction")
        if keys is scores:
            axes.set_ylim(0, 1.02)
        axes.grid(alpha=0.3)
        axes.legend(loc="best", fontsize="small")
    figure.suptitle(title)
    figure.savefig(target, format="png")
