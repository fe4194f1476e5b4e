"""The tracking scoreboard: accumulate a model on one recording, track on another of the same object.

Rows:

- ``sim_<seed>``: a random simulated object (``scene="random"``, fixed seed); the model from a
  24-frame recording at the scene's own drawn motion, tracked over a 30-frame recording of the same
  seed (same object, gripper, background and lighting) at 8 degrees per frame peak yaw rate, with a
  per-frame translation of the object's path up to about 15 mm: a different motion;
- ``dev_steps`` -> ``dev_steps_track`` when ``../shared/data/devset`` exists;
- ``chessboard``: the real board (13 snapshots 1 s apart: every frame is a re-acquisition), model and
  track on the same recording;
- ``teabox`` when ``../shared/data/teabox`` exists: model from frames 0:40, tracked over 40:80 from
  the recorded pose of frame 40 only, judged against the recording's poses (a peer tracker's, not truth);
- ``wrong_model``: the chessboard's model tracked on ``sample_data/sim_box.mcap`` (another object):
  every frame should be ``lost``.

Per row: frames, tracked / ambiguous fractions, median and max rotation (deg) and translation (mm)
errors of the ``tracked`` frames, false confidence (frames ``tracked`` with an error over 3 deg or
5 mm; for the wrong model every ``tracked`` frame), frames per second of the tracking run; then the
median and worst row of each column. ``--only NAME`` runs the rows whose name contains NAME.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import CACHE, ROOT, accumulate_params, recording, score_rows  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
SEEDS = (201, 202, 203, 204, 205, 206)
FALSE_DEG, FALSE_MM = 3.0, 5.0
SECTION = "## Tracking (`benchmarks/track_suite.py`, part of `make suite`)"
NOTE = ("false: frames marked `tracked` with an error over 3 degrees or 5 mm (for the wrong model, every "
        "tracked frame). teabox is judged against the recording's peer-tracker poses.")


@dataclasses.dataclass
class Row:
    name: str
    model_path: str           # the recording the model is accumulated on
    track_path: str           # the recording tracked
    truth: str | None         # truth of track_path (None: the wrong-model row, every tracked frame is false)
    object_frame: str = "gripper"
    model_frames: tuple = (0, None)
    track_frames: tuple = (0, None)
    source: str = "simulated"


def rows() -> list[Row]:
    out = []
    for i, seed in enumerate(SEEDS):
        clutter = i % 3 == 2
        model = recording(f"trk_model_{seed}", frames=24, seed=seed, scene="random", clutter=clutter)
        track = recording(f"trk_track_{seed}", frames=30, seed=seed, scene="random", clutter=clutter,
                          per_frame_deg=8.0)
        out.append(Row(f"sim_{seed}", model, track, track.replace(".mcap", ".truth.json")))
    devset = SHARED / "devset"
    if (devset / "dev_steps_track.mcap").exists():
        out.append(Row("dev_steps", str(devset / "dev_steps.mcap"), str(devset / "dev_steps_track.mcap"),
                       str(devset / "dev_steps_track.truth.json"), source="devset"))
    board = str(ROOT / "sample_data" / "chessboard" / "chessboard")
    out.append(Row("chessboard", f"{board}.mcap", f"{board}.mcap", f"{board}.truth.json", "board", source="real"))
    teabox = SHARED / "teabox" / "teabox"
    if Path(f"{teabox}.mcap").exists():
        out.append(Row("teabox", f"{teabox}.mcap", f"{teabox}.mcap", f"{teabox}.truth.json", "teabox", (0, 40),
                       (40, 80), source="real (peer)"))
    out.append(Row("wrong_model", f"{board}.mcap", str(ROOT / "sample_data" / "sim_box.mcap"), None, "board",
                   source="wrong model"))
    return out


def score(row: Row, view_planes: bool = True, image_confirm: bool = False, across_frames: bool = False) -> dict:
    from accumcli.geometry import pose_error
    from accumcli.model_io import read_truth
    from accumcli.runs import FrameRange, RecordingOptions, accumulate_recording, track_recording

    (CACHE / "track_suite").mkdir(parents=True, exist_ok=True)
    model = accumulate_recording(row.model_path, options=RecordingOptions(object_frame=row.object_frame),
                                 frames=FrameRange(*row.model_frames),
                                 params=accumulate_params(view_planes, image_confirm=image_confirm,
                                                          across_frames=across_frames)).model
    # the wrong model's object frame is not the tracked recording's: it stands for a model of another
    # object in the same frame (track refuses a model of another frame), started at sim_box's recorded pose
    track_frame = "gripper" if row.truth is None else row.object_frame
    model.frame_id = track_frame
    result = track_recording(model, row.track_path, options=RecordingOptions(object_frame=track_frame),
                             frames=FrameRange(*row.track_frames))
    track = result.track
    status = np.array(track.status)
    figures = {"frames": len(status), "tracked": float(np.mean(status == "tracked")),
               "ambiguous": float(np.mean(status == "ambiguous")), "fps": result.frames_per_second}
    if row.truth is None:
        figures["false"] = int(np.sum(status == "tracked"))
        return figures
    truth = read_truth(row.truth)
    errors = np.array([pose_error(T, truth.pose_at(int(t))) for t, T, s in zip(track.times_ns, track.poses, status)
                       if s == "tracked"]).reshape(-1, 2) * [1, 1000]
    if len(errors):
        figures.update(med_deg=float(np.median(errors[:, 0])), max_deg=float(errors[:, 0].max()),
                       med_mm=float(np.median(errors[:, 1])), max_mm=float(errors[:, 1].max()))
    figures["false"] = int(np.sum((errors[:, 0] > FALSE_DEG) | (errors[:, 1] > FALSE_MM)))
    return figures


COLUMNS = [("frames", "frames", None), ("tracked", "tracked", "high"), ("ambig", "ambiguous", None),
           ("med deg", "med_deg", "low"), ("max deg", "max_deg", "low"), ("med mm", "med_mm", "low"),
           ("max mm", "max_mm", "low"), ("false", "false", "low"), ("frames/s", "fps", "high")]


def _cell(value) -> str:
    if value is None:
        return "-"
    return f"{value:.3f}" if isinstance(value, float) else str(value)


def table(results: dict, chosen: list[Row]) -> list[str]:
    lines = ["| row | source | " + " | ".join(c[0] for c in COLUMNS) + " |", "|" + "---|" * (len(COLUMNS) + 2)]
    for row in chosen:
        r = results[row.name]
        if "error" in r:
            lines.append(f"| {row.name} | {row.source} | error: {r['error']} |")
        else:
            lines.append(f"| {row.name} | {row.source} | " + " | ".join(_cell(r.get(k)) for _, k, _ in COLUMNS) + " |")
    # the wrong model's row is judged by its false confidence only (its tracked share should be 0)
    judged = [r for name, r in results.items() if "error" not in r and name != "wrong_model"]
    for label in ("median", "worst"):
        cells = []
        for _, key, better in COLUMNS:
            values = [r[key] for r in judged if r.get(key) is not None]
            if key == "false":
                values += [r["false"] for name, r in results.items() if name == "wrong_model" and "false" in r]
            if not values or better is None:
                cells.append("-")
            elif label == "median":
                cells.append(_cell(float(statistics.median(values))))
            else:
                cells.append(_cell(max(values) if better == "low" else min(values)))
        lines.append(f"| **{label}** | | " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", help="run only the rows whose name contains this")
    parser.add_argument("--average-directions", action="store_true",
                        help="models accumulated with --average-directions (a variant: docs/suite.md is not written)")
    parser.add_argument("--image-confirm", action="store_true",
                        help="models accumulated with --image-confirm (a variant: docs/suite.md is not written)")
    parser.add_argument("--across-frames", action="store_true",
                        help="models accumulated with --across-frames (a variant: docs/suite.md is not written)")
    args = parser.parse_args(argv)
    chosen = [r for r in rows() if not args.only or args.only in r.name]
    t0 = time.perf_counter()
    results = score_rows(chosen, functools.partial(score, view_planes=not args.average_directions,
                                                   image_confirm=args.image_confirm, across_frames=args.across_frames))
    lines = table(results, chosen)
    print("\n".join(lines))
    print(f"\n{len(chosen)} rows in {time.perf_counter() - t0:.0f} s")
    if not args.only and not args.average_directions and not args.image_confirm and not args.across_frames:
        save(lines)
    return 0


def save(lines: list[str]) -> None:
    """Put the table in docs/suite.md as its tracking section (after the extraction scoreboard
    ``suite.py`` wrote), replacing the one there."""
    doc = ROOT / "docs" / "suite.md"
    text = doc.read_text() if doc.exists() else "# The scoreboard (`make suite`)\n"
    head = text.split(f"\n{SECTION}")[0].rstrip("\n")
    doc.write_text(f"{head}\n\n{SECTION}\n\n" + "\n".join(lines) + "\n\n" + NOTE + "\n")


if __name__ == "__main__":
    sys.exit(main())
