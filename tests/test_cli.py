"""The command line: one error line and exit 1 for user errors; help and version."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from accumcli.cli import main

from .test_recording import broken_files

COMMANDS_ON_RECORDINGS = [["info"], ["extract"], ["accumulate"]]


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_version_and_help():
    assert run("--version").output.startswith("accum, version")
    result = run("--help")
    assert result.exit_code == 0 and "Commands:" in result.output


@pytest.mark.parametrize("command", COMMANDS_ON_RECORDINGS, ids=lambda c: c[0])
@pytest.mark.parametrize("case", ["empty", "truncated", "not mcap", "no right", "no calibration",
                                  "missing file"])
def test_bad_recordings_end_in_one_line(tmp_path, command, case):
    path, message = broken_files(tmp_path)[case]
    out = {"extract": ["-o", tmp_path / "out.jsonl"], "accumulate": ["-o", tmp_path / "out.json"]}
    result = run(*command, path, *out.get(command[0], []))
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert lines[-1].startswith("error: ") and message in lines[-1] and str(path) in lines[-1]
    assert "Traceback" not in result.output


def test_renamed_foxglove_topics_are_proposed(tmp_path):
    from . import helpers

    path = helpers.one_pair(tmp_path / "renamed.mcap", image_topic="/cam/{side}/image",
                            calibration_topic="/cam/{side}/calibration", transforms=())
    result = run("info", path)
    assert result.exit_code == 1
    assert ("missing topic /stereo/left/image; the stereo pair looks like: try --left-topic /cam/left/image "
            "--right-topic /cam/right/image --left-calibration-topic /cam/left/calibration "
            "--right-calibration-topic /cam/right/calibration") in result.output


def test_the_images_frame_is_proposed_and_a_different_camera_frame_warned_of(tmp_path):
    from . import helpers

    path = helpers.one_pair(tmp_path / "optical.mcap", frame_id="cam_{side}_optical",
                            transforms=(("cam_left_optical", "gripper", (0.0, 0.0, 0.5)),
                                        ("cam_left_optical", "cam_right_optical", (0.08, 0.0, 0.0))))
    result = run("accumulate", path, "-o", tmp_path / "m.json")
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1].endswith(
        "the images' frame is 'cam_left_optical': try --camera-frame cam_left_optical")
    wrong = run("info", path, "--camera-frame", "cam_right_optical")
    assert ("the left images are in frame 'cam_left_optical' (their frame_id), poses are looked up for "
            "'cam_right_optical'") in wrong.output


def test_frames_that_cannot_be_decoded_are_named_when_nothing_is_left(tmp_path):
    from accumcli.recording import RecordingWriter

    from . import helpers

    path = tmp_path / "big_calibration.mcap"
    with RecordingWriter(path) as w:   # the calibration says 320x240, the images are 160x120
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side, 320, 240), helpers.T0)
        for i in range(3):
            t = helpers.T0 + i * helpers.PERIOD
            w.raw_transform("camera_left", "gripper", (0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0), t)
            for side in ("left", "right"):
                w.image(f"/stereo/{side}/image", helpers.image(i), t, f"camera_{side}", "png")
    result = run("accumulate", path, "-o", tmp_path / "m.json")
    assert result.exit_code == 1
    last = result.output.strip().splitlines()[-1]
    assert "no frame has both images and a pose of 'gripper' in 'camera_left'" in last
    assert "3 frame(s): cannot be decoded (" in last and "160x120" in last
    info = run("info", path).output   # says so before any run
    assert "problem      the images are 160x120, their calibration is for 320x240: every frame would be refused" in info


def test_info_proposes_a_pairing_tolerance_for_unsynchronised_cameras(tmp_path):
    from accumcli.recording import RecordingWriter

    from . import helpers

    path = tmp_path / "jitter.mcap"
    with RecordingWriter(path) as w:   # the right image 0 to 9 ms after the left
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", helpers.calibration(side), helpers.T0)
        for i in range(20):
            t = helpers.T0 + i * helpers.PERIOD
            w.raw_transform("camera_left", "gripper", (0.0, 0.0, 0.5), (0.0, 0.0, 0.0, 1.0), t)
            w.image("/stereo/left/image", helpers.image(i), t, "camera_left", "png")
            w.image("/stereo/right/image", helpers.image(i), t + (i % 10) * 1_000_000, "camera_right", "png")
    result = run("info", path)
    hint = next(line for line in result.output.splitlines() if line.startswith("pairing"))
    tolerance = int(hint.rsplit(" ", 1)[1])
    assert "found no partner within the pairing tolerance" in hint and 9 <= tolerance <= 12
    assert "20 stereo frames" in run("info", path, "--tolerance-ms", tolerance).output


def test_info_reports_missing_object_frame(tmp_path):
    path, _ = broken_files(tmp_path)["no tf"]
    result = run("info", path)
    assert result.exit_code == 1
    assert "error: " in result.output and "no transform path from 'camera_left' to 'gripper'" in result.output


def test_info_summary(small_recording):
    result = run("info", small_recording)
    assert result.exit_code == 0, result.output
    assert "6 stereo frames" in result.output and "320x240 png, rectified" in result.output
    assert "baseline 80.00 mm" in result.output and "gripper in camera_left: 6/6 frames" in result.output


def test_quiet_drops_the_run_report_but_not_the_figures(small_recording, tmp_path):
    """-q: no report of what was done and written on stdout; info's and eval's figures stay."""
    model = tmp_path / "m.json"
    result = run("-q", "accumulate", small_recording, "-o", model, "--frames", "0:3")
    assert result.exit_code == 0 and result.output == "" and model.exists()
    assert "3 frames accumulated" in run("accumulate", small_recording, "-o", model, "--frames", "0:3").output
    assert "6 stereo frames" in run("info", small_recording, "-q").output
    assert "precision" in run("eval", model, small_recording.replace(".mcap", ".truth.json"), "-q").output


@pytest.mark.parametrize("name", ["/dev/stdout", "-"])
def test_an_output_on_stdout_gets_the_output_and_the_report_goes_to_stderr(small_recording, tmp_path, name):
    """-o /dev/stdout with stdout a file: the file was replaced (the shell's redirect lost it), then the
    report overwrote its start. Now the frames go through stdout, whole, and the report to stderr.
    ``-o -`` is the same (it wrote a file named '-')."""
    import json
    import subprocess
    import sys

    (tmp_path / "out.jsonl").write_text("previous\n")
    with open(tmp_path / "out.jsonl", "ab") as stdout:   # a shell's >>: the file is appended to, not truncated
        done = subprocess.run([sys.executable, "-m", "accumcli.cli", "extract", small_recording, "--frames", "0:2",
                               "-o", name], stdout=stdout, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert not (tmp_path / "-").exists()
    first, *lines = (tmp_path / "out.jsonl").read_text().splitlines()
    assert first == "previous"
    assert len(lines) == 2 and all(json.loads(line)["format"] == "accum.model/1" for line in lines)
    assert "wrote /dev/stdout" in done.stderr


def test_every_output_named_dash_is_the_standard_output(small_recording, tmp_path):
    """--png - (as -o -): the picture on stdout, no file named '-' (view, accumulate's --png/--history/
    --plot/--panel/--rrd, track's and extract's --rrd, eval's --plot all wrote one)."""
    import subprocess
    import sys

    model = tmp_path / "m.json"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    done = subprocess.run([sys.executable, "-m", "accumcli.cli", "view", str(model), "--png", "-"], capture_output=True,
                          cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.startswith(b"\x89PNG") and not (tmp_path / "-").exists()
    assert b"wrote /dev/stdout" in done.stderr


def test_simulate_rejects_bad_options(tmp_path):
    result = run("simulate", "-o", tmp_path / "x.mcap", "--pose-noise", "abc")
    assert result.exit_code == 1 and "expected DEG,MM" in result.output
    result = run("simulate", "-o", tmp_path / "missing" / "x.mcap", "--count", "1", "--size", "64x48")
    assert result.exit_code == 1 and "does not exist" in result.output
    result = run("simulate", "-o", tmp_path / "x.mcap", "--count", "1", "--distortion", "fisheye")
    assert result.exit_code == 1 and "applies to raw images only; add --raw" in result.output


def test_accumulate_without_transforms_is_a_whole_file_error(tmp_path):
    path, _ = broken_files(tmp_path)["no tf"]
    result = run("accumulate", path, "-o", tmp_path / "model.json")
    assert result.exit_code == 1 and "missing topic /tf" in result.output.strip().splitlines()[-1]


def test_extract_needs_no_object_pose(tmp_path):
    """Extraction is in the camera frame: a recording without transforms extracts, without a pose field."""
    import json

    path, _ = broken_files(tmp_path)["no tf"]
    out = tmp_path / "frames.jsonl"
    result = run("extract", path, "-o", out)
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == 5 and all("T_camera_object" not in d for d in lines)


def test_extract_writes_one_line_per_frame(small_recording, tmp_path):
    import json

    out = tmp_path / "frames.jsonl"
    result = run("extract", small_recording, "-o", out, "--frames", "1:4")
    assert result.exit_code == 0, result.output
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [d["frame_index"] for d in lines] == [1, 2, 3]
    assert all(d["format"] == "accum.model/1" and d["frame_id"] == "camera_left" for d in lines)
    assert all("timestamp_ns" in d and len(d["segments"]) > 20 for d in lines)
    assert "3D segments per frame" in result.output and "critical" in result.output
    figures = run("eval", out, small_recording.replace(".mcap", ".truth.json"), "--json")
    assert json.loads(figures.output)["accuracy_near_object"] > 0.8


def test_gradient_blur_reaches_extraction(small_recording, tmp_path):
    """``--gradient-blur``: the blur before the gradients (default 0.5); less of it keeps more edge
    detail (more 3D segments here), and a value out of its range is refused in one line."""
    import json

    counts = []
    for blur in ("0.5", "1.0"):
        out = tmp_path / f"frames_{blur}.jsonl"
        result = run("extract", small_recording, "-o", out, "--frames", "1:3", "--gradient-blur", blur)
        assert result.exit_code == 0, result.output
        counts.append(sum(len(json.loads(line)["segments"]) for line in out.read_text().splitlines()))
    default = tmp_path / "frames.jsonl"
    assert run("extract", small_recording, "-o", default, "--frames", "1:3").exit_code == 0
    assert sum(len(json.loads(line)["segments"]) for line in default.read_text().splitlines()) == counts[0]
    assert counts[0] > counts[1]
    refused = run("extract", small_recording, "-o", tmp_path / "x.jsonl", "--gradient-blur", "-1")
    assert refused.exit_code != 0 and "gradient-blur" in refused.output


def _board_counts(tmp_path, flags, keys):
    """Per flag (None: none): the sums over the chessboard's first two frames of ``accum extract``'s
    counts ``keys``."""
    import json
    from pathlib import Path

    board = Path(__file__).resolve().parent.parent / "sample_data" / "chessboard" / "chessboard.mcap"
    counts = {}
    for flag in flags:
        out = tmp_path / f"frames{flag or ''}.jsonl"
        assert run("extract", str(board), "-o", out, "--frames", "0:2", *([flag] if flag else [])).exit_code == 0
        lines = [json.loads(line)["counts"] for line in out.read_text().splitlines()]
        counts[flag] = tuple(sum(c[key] for c in lines) for key in keys)
    return counts


def test_critical_ends_can_be_switched_off_for_the_papers_rule(tmp_path):
    counts = _board_counts(tmp_path, ("--critical-ends", "--no-critical-ends"), ("critical_3d", "critical"))
    assert counts["--critical-ends"][0] > 0 and counts["--no-critical-ends"][0] == 0
    assert counts["--critical-ends"][1] == counts["--no-critical-ends"][1] > 0


def test_right_search_is_off_by_default_and_can_be_switched_on(tmp_path):
    counts = _board_counts(tmp_path, (None, "--right-search", "--no-right-search"), ("segments", "right_found"))
    assert counts[None] == counts["--no-right-search"] and counts["--no-right-search"][1] == 0
    assert counts["--right-search"][1] > 0 and counts["--right-search"][0] > counts["--no-right-search"][0]


def test_accumulate_then_eval(small_recording, tmp_path):
    import json

    truth = small_recording.replace(".mcap", ".truth.json")
    model, ply, history = tmp_path / "m.json", tmp_path / "m.ply", tmp_path / "h.jsonl"
    result = run("accumulate", small_recording, "-o", model, "-o", ply, "--truth", truth, "--history", history)
    assert result.exit_code == 0, result.output
    assert model.exists() and ply.exists() and len(history.read_text().splitlines()) == 6

    def refuse(constant):
        raise ValueError(f"bare {constant} is not JSON")
    rows = [json.loads(line, parse_constant=refuse) for line in history.read_text().splitlines()]
    assert rows[0]["precision"] is None   # no accepted segment after one frame: null, never NaN
    figures = json.loads(run("eval", model, truth, "--json").output)
    assert figures["accepted"] > 20 and figures["precision"] > 0.85 and figures["background"] < 0.05


def test_a_box_keeps_the_model_inside_it(small_recording, tmp_path):
    """--box drops 3D segments centred outside it (object frame) before the update: the boxed model lies
    in the box and holds about what the whole model holds there; a box around nothing is an error."""
    import numpy as np

    from accumcli.geometry import inside_box
    from accumcli.model_io import read_model, read_truth

    truth = read_truth(small_recording.replace(".mcap", ".truth.json"))
    ends = np.vstack([truth.a, truth.b])
    box = np.column_stack([ends.min(axis=0) - 0.01, ends.max(axis=0) + 0.01])
    box[0, 0] = np.median(ends[:, 0])                       # the object's far half in x only
    text = ",".join(f"{lo:.4f}:{hi:.4f}" for lo, hi in box)
    whole, boxed = tmp_path / "whole.json", tmp_path / "boxed.json"
    assert run("accumulate", small_recording, "-o", whole).exit_code == 0
    result = run("accumulate", small_recording, "-o", boxed, "--box", text)
    assert result.exit_code == 0, result.output
    dropped, total = (int(x) for x in result.output.split("box: ")[1].split(" 3D segments")[0].split(" of "))
    assert 0 < dropped < total
    inside = read_model(boxed)
    assert inside_box(inside.centers, box + [[-0.001, 0.001]]).all()
    everything = read_model(whole)
    accepted_there = inside_box(everything.centers, box) & everything.accepted
    assert inside.accepted.sum() >= 0.7 * accepted_there.sum() > 0
    far = ",".join(f"{lo + 1:.4f}:{hi + 1:.4f}" for lo, hi in box)
    nothing = run("accumulate", small_recording, "-o", tmp_path / "none.json", "--box", far)
    assert nothing.exit_code == 1 and "3D segments of 6 frames lay outside --box" in nothing.output
    assert not (tmp_path / "none.json").exists()


def test_no_frame_with_a_pose_is_an_error_not_an_empty_model(tmp_path):
    from . import helpers

    path = helpers.write(tmp_path / "late_tf.mcap", n=3, tf_times=[helpers.T0 + k * helpers.PERIOD for k in (10, 11, 12)])
    result = run("accumulate", path, "-o", tmp_path / "m.json")
    assert result.exit_code == 1 and not (tmp_path / "m.json").exists()
    assert "no frame has both images and a pose of 'gripper'" in result.output.strip().splitlines()[-1]


def test_frames_without_pose_are_skipped_with_a_warning(small_recording, tmp_path):
    from accumcli.recording import Recording, RecordingWriter

    path = tmp_path / "short_tf.mcap"   # the small recording's images, /tf only for its first 4 frames
    with Recording(small_recording) as rec, RecordingWriter(path) as w:
        for side in ("left", "right"):
            w.calibration(f"/stereo/{side}/calibration", rec.calibrations[side][0][1], rec.calibrations[side][0][0])
        for frame in rec.frames():
            if frame.index < 4:
                w.transform("camera_left", "gripper", frame.T_camera_object, frame.timestamp_ns)
            w.image("/stereo/left/image", frame.left, frame.timestamp_ns, "camera_left", "png")
            w.image("/stereo/right/image", frame.right, frame.timestamp_ns, "camera_right", "png")
    result = run("accumulate", path, "-o", tmp_path / "m.json")
    assert result.exit_code == 0, result.output
    assert result.output.count("warning:") == 2 and "frame 4: no pose" in result.output
    assert "2 skipped without a pose" in result.output
    empty = run("accumulate", helpers_empty(tmp_path), "-o", tmp_path / "e.json")   # flat images: no segment
    assert empty.exit_code == 1 and "the model is empty: no 3D segment was extracted" in empty.output
    info = run("info", path)   # the reason, once for the frames it holds for
    assert "2 frame(s): camera_left -> gripper: outside the transform samples [" in info.output


def helpers_empty(tmp_path):
    """A recording whose flat grey images show no edge (noise of 0 to 255 grey levels shows corners
    everywhere, and a few of its pieces happen to match)."""
    from . import helpers

    return helpers.write(tmp_path / "flat.mcap", n=3, images=lambda i: np.full((120, 160), 128, np.uint8))


@pytest.mark.parametrize("args, message", [
    (["--so", "90"], "not in the range"),
    (["--detector", "canny"], "'canny' is not one of"),
    (["--depth-range", "2:1"], "expected MIN:MAX"),
    (["-o", "nowhere/m.json"], "the folder nowhere does not exist"),
    (["-o", "m.txt"], "expected a .json, .ply or .mcap"),
    (["-o", "-"], "found the standard output (- or /dev/stdout), which has no name to tell the format by: write a file"),
    (["-o", "/dev/stderr"], "found the stream /dev/stderr, which has no name to tell the format by"),
    (["--frames", "10"], "expected START:STOP, found '10' (frame 10 alone is 10:11, the first 10 frames are 0:10)"),
    (["--frames", "5:2"], "expected START < STOP"),
    (["--box", "0:1,0:1"], "expected X0:X1,Y0:Y1,Z0:Z1 (metres, object frame), found '0:1,0:1'"),
    (["--box", "0:1,0:1,1:0"], "with each minimum below its maximum"),
    (["--box=-60:60,-200:50,-50:50"], "a box 250 m across, found '-60:60,-200:50,-50:50' (millimetres? give metres)"),
    (["--frames", "50:60"], "frames 50:60 select no frame: the recording has 6 stereo frames (0:6)"),
])
def test_accumulate_validates_options(small_recording, tmp_path, monkeypatch, args, message):
    """Every mistake: one line, exit 1, before any output is written."""
    monkeypatch.chdir(tmp_path)
    base = ["accumulate", small_recording] + ([] if "-o" in args else ["-o", "m.json"])
    result = run(*base, *args)
    assert result.exit_code == 1 and message in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1 and result.output.startswith("error: ")
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_and_verbose_go_before_or_after_the_command(small_recording, tmp_path, where):
    args = ["extract", small_recording, "-o", tmp_path / "f.jsonl", "--frames", "0:1"]
    verbose = run("-v", *args) if where == "before" else run(*args, "-v")
    assert verbose.exit_code == 0 and "stereo frames, 1 calibration message(s)" in verbose.output
    quiet = run("-q", *args) if where == "before" else run(*args, "-q")
    assert quiet.exit_code == 0 and "calibration message" not in quiet.output


@pytest.mark.parametrize("command", [["extract"], ["accumulate"], ["view", "--png", "{input}"]], ids=lambda c: c[0])
def test_an_output_never_replaces_an_input(small_recording, tmp_path, command):
    import shutil

    recording = tmp_path / "run.mcap"
    shutil.copy(small_recording, recording)
    before = recording.read_bytes()
    args = [a.replace("{input}", str(recording)) for a in command[1:]] or ["-o", recording]
    result = run(command[0], recording, *args)
    assert result.exit_code == 1 and "is also an input of this run" in result.output.strip().splitlines()[-1]
    assert recording.read_bytes() == before


def test_eval_refuses_the_truth_of_another_object(small_recording, tmp_path):
    import json

    model = tmp_path / "m.json"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    other = tmp_path / "other.truth.json"
    other.write_text(json.dumps({"format": "accum.truth/1", "object_frame": "board", "camera_frame": "camera_left",
                                 "edges": [{"a": [0, 0, 0], "b": [0.1, 0, 0]}], "poses": []}))
    result = run("eval", model, other)
    assert result.exit_code == 1
    assert "the truth is of object frame 'board', the model of 'gripper'" in result.output
    assert "(or the model of a run with --object-frame board)" in result.output   # eval has no such option


def test_a_truth_or_poses_of_other_times_are_refused_everywhere(small_recording, tmp_path):
    import json

    truth = json.loads(open(small_recording.replace(".mcap", ".truth.json")).read())
    for pose in truth["poses"]:
        pose["timestamp_ns"] += 10 ** 12          # the same object, recorded 1000 s later
    other = tmp_path / "later.truth.json"
    other.write_text(json.dumps(truth))
    model = tmp_path / "m.json"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    assert json.loads(model.read_text())["source_times_ns"][0] > 0
    poses = tmp_path / "p.json"
    poses.write_text(json.dumps({"format": "accum.poses/1", "parent_frame_id": "camera_left", "child_frame_id": "gripper",
                                 "poses": [{**p, "status": "tracked"} for p in truth["poses"]]}))
    for args in (["eval", model, other], ["accumulate", small_recording, "-o", tmp_path / "m2.json", "--truth", other],
                 ["view", small_recording, model, poses, "--png", tmp_path / "v.png"]):
        result = run(*args)
        assert result.exit_code == 1, args
        assert "lie outside those of" in result.output and "is it of another recording?" in result.output
    assert not (tmp_path / "m2.json").exists() and not (tmp_path / "v.png").exists()


def test_a_truth_of_another_recording_at_the_same_times_is_refused(small_recording, tmp_path):
    """The truth of another recording made at the same times (another object, its poses a quarter turn
    away): the run and the frames file's evaluation refuse it by the recorded poses; a model has none,
    and its evaluation warns that nothing lies on the truth's edges."""
    import json

    import numpy as np
    from scipy.spatial.transform import Rotation

    truth = json.loads(open(small_recording.replace(".mcap", ".truth.json")).read())
    quarter = Rotation.from_euler("z", 90, degrees=True)
    for pose in truth["poses"]:
        pose["rotation_xyzw"] = (Rotation.from_quat(pose["rotation_xyzw"]) * quarter).as_quat().tolist()
        pose["translation"] = (np.asarray(pose["translation"]) + [0.05, 0.0, 0.0]).tolist()
    for edge in truth["edges"]:
        edge["a"], edge["b"] = ([x + 0.2 for x in edge[end]] for end in ("a", "b"))
    other = tmp_path / "other.truth.json"
    other.write_text(json.dumps(truth))
    frames, model = tmp_path / "f.jsonl", tmp_path / "m.json"
    assert run("extract", small_recording, "-o", frames, "--frames", "0:2").exit_code == 0
    assert run("accumulate", small_recording, "-o", model).exit_code == 0
    for args in (["eval", frames, other], ["accumulate", small_recording, "-o", tmp_path / "m2.json", "--truth", other]):
        result = run(*args)
        assert result.exit_code == 1, args
        assert "lie a median 90 deg and 50 mm from the truth's: is it the truth of another recording" in result.output
    assert not (tmp_path / "m2.json").exists()
    assert run("eval", frames, small_recording.replace(".mcap", ".truth.json")).exit_code == 0
    result = run("eval", model, other)
    assert result.exit_code == 0 and "lies on an edge of" in result.output


def test_eval_refuses_poses_of_another_recording(small_recording, tmp_path):
    import json

    poses = tmp_path / "p.json"
    poses.write_text(json.dumps({"format": "accum.poses/1", "parent_frame_id": "camera_left",
                                 "child_frame_id": "gripper", "poses": [
                                     {"timestamp_ns": 5, "translation": [0, 0, 0.5], "rotation_xyzw": [0, 0, 0, 1],
                                      "status": "tracked"}]}))
    result = run("eval", poses, small_recording.replace(".mcap", ".truth.json"))
    assert result.exit_code == 1 and "is it the truth of another recording?" in result.output


def test_eval_of_a_ply_names_the_kind(small_recording, tmp_path):
    ply = tmp_path / "m.ply"
    assert run("accumulate", small_recording, "-o", ply, "--frames", "0:2").exit_code == 0
    result = run("eval", ply, small_recording.replace(".mcap", ".truth.json"))
    assert result.exit_code == 1 and "PLY" in result.output and "Traceback" not in result.output


def test_view_of_a_model_named_with_spaces_prints_nothing_of_rerun(small_recording, tmp_path):
    """A model's file name becomes its entity path: spaces unescaped made Rerun warn on stderr."""
    import subprocess
    import sys

    model = tmp_path / "my model ü.json"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    done = subprocess.run([sys.executable, "-m", "accumcli.cli", "view", str(model), "--rrd", str(tmp_path / "v.rrd")],
                          capture_output=True, text=True)
    assert done.returncode == 0 and done.stderr == "" and "wrote" in done.stdout, done.stderr


def test_view_writes_rrd_and_png(small_recording, tmp_path):
    model = tmp_path / "m.json"
    run("accumulate", small_recording, "-o", model)
    result = run("view", small_recording, model, "--rrd", tmp_path / "v.rrd", "--png", tmp_path / "v.png")
    assert result.exit_code == 0, result.output
    assert (tmp_path / "v.rrd").stat().st_size > 10000 and (tmp_path / "v.png").stat().st_size > 1000
    nothing = run("view", model)   # nothing to do without an output
    assert nothing.exit_code == 1 and "nothing to do: give --rrd" in nothing.output


def test_view_warns_of_a_model_that_does_not_fit_the_images(small_recording, tf_tree_recording, tmp_path):
    """A model of another object (the house of another recording) drawn at the recording's poses is named in a
    warning, in the picture and in the Rerun view; the object's own model is not."""
    model, other = tmp_path / "m.json", tmp_path / "house.json"
    assert run("accumulate", small_recording, "-o", model).exit_code == 0
    assert run("accumulate", tf_tree_recording, "-o", other).exit_code == 0
    for outputs in (["--png", tmp_path / "v.png"], ["--rrd", tmp_path / "v.rrd"]):
        own = run("view", small_recording, model, *outputs)
        assert own.exit_code == 0 and "does not fit" not in own.output
        foreign = run("view", small_recording, other, *outputs)
        assert foreign.exit_code == 0
        assert "house does not fit frame" in foreign.output and "a model of another object" in foreign.output


def test_view_png_draws_every_model_and_the_truth(small_recording, tmp_path):
    """Every model of the inputs gets its panel (it drew the first alone), the truth's edges lie under each."""
    import cv2

    first, second = tmp_path / "a.json", tmp_path / "b.json"
    assert run("accumulate", small_recording, "-o", first, "--frames", "0:3").exit_code == 0
    assert run("accumulate", small_recording, "-o", second, "--frames", "3:6").exit_code == 0
    truth = small_recording.replace(".mcap", ".truth.json")
    for inputs, panels in (([first, second, truth], 2), ([small_recording, first, second, truth], 4)):
        assert run("view", *inputs, "--png", tmp_path / "v.png").exit_code == 0
        image = cv2.imread(str(tmp_path / "v.png"))
        width = 640 if panels == 2 else 320   # the small recording's images are 320 px wide
        assert image.shape[1] == panels * width + 4 * (panels - 1)
        magenta = (image[..., 1] < 120) & (image[..., 0] > 200) & (image[..., 2] > 200)
        assert magenta[:, -width:].sum() > 20


@pytest.mark.parametrize("defect, message", [
    ({"corrupt_left": (2,)}, "frame 2 (1.200 s): cannot decode png image bytes"),
    ({"unpaired_right": (1,)}, "has no partner within 1.000 ms: skipped"),
])
def test_a_bad_frame_is_a_warning_and_the_others_go_on(tmp_path, defect, message):
    import json

    from . import helpers

    path = helpers.write(tmp_path / "defect.mcap", n=5, **defect)
    out = tmp_path / "frames.jsonl"
    result = run("extract", path, "-o", out)
    assert result.exit_code == 0, result.output
    assert any(line.startswith("warning: ") and message in line for line in result.output.splitlines())
    assert len(out.read_text().splitlines()) == 4
    assert all(json.loads(line)["format"] == "accum.model/1" for line in out.read_text().splitlines())


def test_extraction_is_deterministic_across_processes(small_recording, tmp_path):
    """Same input, same bytes out: in separate processes (memory alignment differs between them,
    and some of OpenCV's SIMD paths round differently with it)."""
    import subprocess
    import sys

    outputs = []
    for i in range(2):
        out = tmp_path / f"frames{i}.jsonl"
        subprocess.run([sys.executable, "-m", "accumcli.cli", "-q", "extract", small_recording, "-o", str(out)],
                       check=True, capture_output=True)
        outputs.append(out.read_bytes())
    assert outputs[0] == outputs[1]


@pytest.mark.parametrize("signum, delay", [("SIGINT", 0.4), ("SIGINT", 1.5), ("SIGTERM", 0.4), ("SIGTERM", 1.5)])
def test_an_interrupt_leaves_the_previous_output_and_no_temporary(tmp_path, signum, delay):
    """Ctrl-C or SIGTERM, during the imports or during the work: one line, exit 130, the old model kept."""
    import os
    import signal

    model = tmp_path / "m.json"
    model.write_text("previous")
    process = _accum_started(["accumulate", "sample_data/sim_box.mcap", "-o", str(model)], delay)
    process.send_signal(getattr(signal, signum))
    out, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().endswith("error: interrupted") and "Traceback" not in err, err
    assert model.read_text() == "previous" and os.listdir(tmp_path) == ["m.json"]


@pytest.mark.parametrize("signum, delay", [("SIGTERM", 1.0), ("SIGINT", 1.5)])
def test_a_signal_to_the_process_group_with_extraction_helpers(tmp_path, signum, delay):
    """As Ctrl-C in a terminal, ``timeout`` or a service manager do: the signal reaches the helper
    processes too, which died of it (a BrokenProcessPool traceback, or a helper's KeyboardInterrupt).
    Now one line and exit 130 (or the run had finished), and no process of the group is left."""
    import os
    import signal
    import time

    process = _accum_started(["extract", "sample_data/sim_box.mcap", "-o", str(tmp_path / "f.jsonl"), "--workers",
                              "2"], delay, start_new_session=True)
    os.killpg(process.pid, getattr(signal, signum))
    out, err = process.communicate(timeout=60)
    assert "Traceback" not in err, err
    assert (process.returncode == 130 and err.strip().endswith("error: interrupted")) or (
        process.returncode == 0 and "wrote" in out), err
    for _ in range(50):   # the fork server and its helpers end with the run
        try:
            os.killpg(process.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.1)
    else:
        pytest.fail("processes of the run's group are left")


def _accum_started(args: list, delay: float, **popen):
    """The ``accum`` command line running ``args`` from the repository, ``delay`` seconds after its
    SIGTERM handler is in. SIGINT as a terminal's foreground command has it: a runner started in the
    background (``cmd &`` in a script) ignores SIGINT, and its children would inherit that (Python
    keeps an ignored SIGINT)."""
    import os
    import shutil
    import signal
    import subprocess
    import sys
    import time

    accum = shutil.which("accum", path=os.path.dirname(sys.executable)) or shutil.which("accum")
    process = subprocess.Popen([accum, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=os.path.dirname(os.path.dirname(__file__)),
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL), **popen)
    _wait_until_it_catches_sigterm(process.pid)
    time.sleep(delay)
    return process


def _wait_until_it_catches_sigterm(pid: int) -> None:
    """Until the process's SIGTERM handler is in (the entry point's first act): before it, in the
    interpreter's own start-up, SIGTERM kills by default. The delays after it were counted from the
    start, and on a loaded machine 0.4 s sometimes fell inside the start-up (exit -15, a flaky test)."""
    import os
    import time

    if not os.path.exists(f"/proc/{pid}/status"):   # no /proc (macOS): the delays count from the start
        return
    for _ in range(200):
        with open(f"/proc/{pid}/status") as f:
            caught = int(next(line for line in f if line.startswith("SigCgt:")).split()[1], 16)
        if caught >> (15 - 1) & 1:
            return
        time.sleep(0.01)


def _wrapped_interrupt(*args, **kwargs):
    """What numba does with a KeyboardInterrupt raised while it loads a cached kernel."""
    try:
        raise KeyboardInterrupt("SIGTERM")
    except KeyboardInterrupt as e:
        raise SystemError("<function _numba_unpickle> returned a result with an exception set") from e


def test_an_interrupt_wrapped_by_compiled_code_is_an_interrupt(small_recording, tmp_path, monkeypatch):
    """A signal landing in numba's first-call dispatch (seen in CI) ends as Ctrl-C does; any other
    SystemError is a bug and keeps its traceback."""
    import os

    import accumcli.runs

    model = tmp_path / "m.json"
    model.write_text("previous")
    monkeypatch.setattr(accumcli.runs, "accumulate_recording", _wrapped_interrupt)
    result = run("accumulate", small_recording, "-o", model)
    assert result.exit_code == 130 and result.output.strip().splitlines()[-1] == "error: interrupted"
    assert model.read_text() == "previous" and os.listdir(tmp_path) == ["m.json"]

    def bug(*args, **kwargs):
        raise SystemError("a real bug")

    monkeypatch.setattr(accumcli.runs, "accumulate_recording", bug)
    result = run("accumulate", small_recording, "-o", model)
    assert result.exit_code == 1 and isinstance(result.exception, SystemError)


def test_an_interrupt_that_c_code_replaced_by_another_error_is_an_interrupt(small_recording, tmp_path, monkeypatch):
    """numpy's comparison of structured arrays (np.unique(..., axis=0)) turned the KeyboardInterrupt of
    a SIGTERM into a TypeError traceback (a fresh clone's CI, 1 in 4 runs of the interrupt test under
    load): any error after the process was sent an interrupt ends as the interrupt does; without one,
    the same error is a bug and keeps its traceback."""
    import accumcli.runs
    from accumcli import outputs

    def interrupted_in_numpy(*args, **kwargs):
        outputs._received.append(15)   # what the SIGTERM handler notes before it raises
        raise TypeError("Cannot compare structured arrays unless they have a common dtype.")

    monkeypatch.setattr(outputs, "_received", [])
    monkeypatch.setattr(accumcli.runs, "accumulate_recording", interrupted_in_numpy)
    result = run("accumulate", small_recording, "-o", tmp_path / "m.json")
    assert result.exit_code == 130 and result.output.strip().splitlines()[-1] == "error: interrupted"
    monkeypatch.setattr(outputs, "_received", [])
    monkeypatch.setattr(accumcli.runs, "accumulate_recording", lambda *a, **k: [][1])
    result = run("accumulate", small_recording, "-o", tmp_path / "m.json")
    assert result.exit_code == 1 and isinstance(result.exception, IndexError)


def test_a_rosbag2_folder_is_a_recording_for_every_command(small_recording, tmp_path):
    from accumcli.recording import Rosbag2Writer
    from accumcli.recording.ros2 import convert_to_ros2

    bag = tmp_path / "bag"
    with Rosbag2Writer(bag) as writer:
        convert_to_ros2(small_recording, writer)
    info = run("info", bag)
    assert info.exit_code == 0 and "6 stereo frames" in info.output and "sensor_msgs/msg/CompressedImage" in info.output
    assert run("accumulate", bag, "-o", tmp_path / "m.json", "--frames", "0:2").exit_code == 0
    assert run("accumulate", small_recording, "-o", tmp_path / "p.json", "--frames", "0:2").exit_code == 0
    assert (tmp_path / "m.json").read_bytes() == (tmp_path / "p.json").read_bytes()
    assert run("view", bag, tmp_path / "m.json", "--png", tmp_path / "v.png").exit_code == 0


def test_detector_choices_are_the_librarys():
    """The CLI offers every detector the library has, with the library's default."""
    import click

    from accumcli.lines2d import DETECTORS, LineParams

    option = next(p for p in main.commands["extract"].params if p.name == "detector")
    assert isinstance(option.type, click.Choice) and set(option.type.choices) == set(DETECTORS)
    assert option.default == LineParams().detector


def test_progress_of_motion_tracked_covers_every_pass(small_recording):
    """One bar over every pass, each pass's frames weighted by their cost (the first pass, extraction,
    is 4 of the 10 parts): the bar ends full, not after the first fifth, and its ETA holds early."""
    from accumcli.pipeline import AccumulateParams
    from accumcli.runs import accumulate_recording
    from accumcli.runs.accumulation import TRACKED_PASS_COST

    calls = []
    accumulate_recording(small_recording, params=AccumulateParams(motion="tracked"),
                         progress=lambda done, total: calls.append((done, total)))
    total = 6 * sum(TRACKED_PASS_COST)
    assert calls[-1] == (total, total) and len(calls) == 6 * len(TRACKED_PASS_COST)
    assert calls[5][0] == 6 * TRACKED_PASS_COST[0] == 0.4 * total   # the first pass: 4 tenths


@pytest.mark.parametrize("args, message", [
    (["accumulate", "{rec}", "-o", "{tmp}/m.json", "--all"], "--all chooses what a .ply output holds"),
    (["view", "{rec}", "{model}", "--png", "{tmp}/v.png", "--png-frame", "4", "--frames", "0:2"],
     "--png-frame 4 lies outside --frames 0:2"),
    (["eval", "{model}", "{truth}", "--plot", "{tmp}/p.png"], "--plot draws a frames file's figures"),
    (["eval", "{model}", "{truth}", "--frames", "0:1"], "--frames selects lines of a frames or poses file"),
    (["eval", "{frames}", "{truth}", "--frames", "9:"], "--frames 9: selects no line (the file has 2)"),
])
def test_an_option_that_would_do_nothing_is_an_error(small_recording, tmp_path, args, message):
    model, frames = tmp_path / "m0.json", tmp_path / "f.jsonl"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    assert run("extract", small_recording, "-o", frames, "--frames", "0:2").exit_code == 0
    names = dict(rec=small_recording, tmp=tmp_path, model=model, frames=frames,
                 truth=small_recording.replace(".mcap", ".truth.json"))
    result = run(*[a.format(**names) for a in args])
    assert result.exit_code == 1 and message in result.output.strip().splitlines()[-1], result.output
    assert not any(p.name in ("m.json", "v.png", "p.png") for p in tmp_path.iterdir())


def test_library_runs_take_one_path_or_a_list_and_refuse_other_types(small_recording, tmp_path):
    from accumcli.errors import InputError
    from accumcli.runs import accumulate_recording, extract_recording, track_recording, view

    model = tmp_path / "mdl.json"
    assert accumulate_recording(small_recording, str(model), frames="0:2").outputs == [str(model)]   # not m, d, l...
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mdl.json"]
    assert track_recording(str(model), small_recording, tmp_path / "p.json", frames="0:2").outputs == [str(tmp_path / "p.json")]
    view(str(model), png=str(tmp_path / "m.png"))
    for call, message in ((lambda: accumulate_recording(small_recording, 5), "outputs: expected a path or a list"),
                          (lambda: track_recording({}, small_recording), "model: expected a model file's path"),
                          (lambda: extract_recording(small_recording, ["a.jsonl", "b.jsonl"]), "expected one frames file"),
                          (lambda: accumulate_recording(small_recording, frames=3), "frames: expected a FrameRange")):
        with pytest.raises(InputError, match=message):
            call()


def test_track_takes_the_models_object_frame_unless_one_is_given(small_recording, tmp_path):
    import json
    import re

    model = tmp_path / "m.json"
    assert run("accumulate", small_recording, "-o", model, "--frames", "0:2").exit_code == 0
    doc = json.loads(model.read_text())
    doc["frame_id"] = "board"
    model.write_text(json.dumps(doc))
    # --object-frame wins: the same object under another name is tracked, with a warning
    result = run("track", model, small_recording, "-o", tmp_path / "p.json", "--object-frame", "gripper")
    assert result.exit_code == 0 and "the model is in frame 'board', tracked as the recording's 'gripper'" in result.output
    tracked = re.search(r"(\d+) frames: (\d+) tracked", result.output)
    assert tracked and int(tracked.group(2)) > 0      # the same object: its frames are tracked
    # without --object-frame the model's frame is the object's: this recording has none of that name
    result = run("track", model, small_recording, "-o", tmp_path / "p.json")
    assert result.exit_code == 1 and "no transform path from 'camera_left' to 'board'" in result.output


def test_a_sigterm_after_the_command_succeeded_changes_nothing():
    """A SIGTERM while the interpreter shuts down after a successful command (its outputs in place)
    is ignored: it ended the process with exit 143 and no word (a user's script polling for the
    outputs, then stopping the process)."""
    import subprocess
    import sys

    code = ("import atexit, os, signal, sys, time\n"
            "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGTERM), time.sleep(0.2)))\n"
            "sys.argv = ['accum', '--help']\n"
            "from accumcli.entry import main\n"
            "main()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, (done.returncode, done.stderr[-500:])
    assert "Usage" in done.stdout and done.stderr == ""


def test_frames_without_a_pose_at_their_times_are_one_reason_with_a_word_on_the_clocks():
    """A camera stamping from its boot (1234 s) and transforms from 1970: 36 reasons that differ only in
    the frame's time are one, with the range of times and a remark on the clocks."""
    from accumcli.runs.base import nothing_done

    reasons = {f"base_link -> tool0: time {1234 + i / 10:.3f} s is outside the transform samples "
               "[1749999999.800, 1750000003.700] s": 1 for i in range(36)}
    reasons["image decode failed"] = 2
    message = str(nothing_done("bag", "nothing was accumulated", reasons))
    assert message.count("frame(s)") == 2 and len(message) < 400, message
    assert ("36 frame(s): base_link -> tool0: time 1234.000 to 1237.500 s is outside the transform samples "
            "[1749999999.800, 1750000003.700] s, 1749998762 s away: the images and the transforms seem to be "
            "stamped by different clocks; record both with one clock, or if both began together try "
            "--time-offset-ms 1749998765801") in message
    near = {"a -> b: time 10.000 s is outside the transform samples [10.500, 20.000] s": 1}
    assert "clocks" not in str(nothing_done("bag", "nothing", near))



def test_plane_agreement_needs_view_planes(tmp_path):
    """--plane-agreement tests the planes of --view-planes: with --average-directions it is refused in
    one line before any work (no model written)."""
    result = run("accumulate", "sample_data/sim_box.mcap", "-o", tmp_path / "m.json", "--plane-agreement", "0.006", "--average-directions")
    assert result.exit_code != 0 and "--average-directions has none" in result.output
    assert not (tmp_path / "m.json").exists()


@pytest.mark.parametrize("option", ["--image-confirm", "--across-frames"])
def test_options_that_trust_the_recorded_poses_are_refused_with_tracked_motion(tmp_path, option):
    """--image-confirm judges segments on the images at the recorded poses, --across-frames trusts the
    relative poses to a tenth of a degree; --motion tracked fits the poses to the same images, half a
    degree off: refused in one line, exit 1, no model written."""
    result = run("accumulate", "sample_data/sim_box.mcap", "-o", tmp_path / "m.json", option, "--motion", "tracked")
    assert result.exit_code == 1 and f"{option} needs the recorded poses" in result.output
    assert "Traceback" not in result.output and len(result.output.strip().splitlines()) == 1
    assert not (tmp_path / "m.json").exists()


def test_across_frames_adds_lines_triangulated_across_frames_and_says_how_many(tmp_path):
    """--across-frames: the report counts the lines across frames among the 3D segments, each
    history row carries its frame's count, and the model, judged against the truth, is at least as
    complete as the stereo-only default at a precision of 0.95 or more."""
    import json

    scores = {}
    for name, extra in (("default", []), ("across", ["--across-frames"])):
        result = run("accumulate", "sample_data/sim_box.mcap", "-o", tmp_path / f"{name}.json", "--truth",
                     "sample_data/sim_box.truth.json", "--history", tmp_path / f"{name}.jsonl", *extra)
        assert result.exit_code == 0, result.output
        rows = [json.loads(line) for line in (tmp_path / f"{name}.jsonl").read_text().splitlines()]
        scores[name] = rows[-1]      # the model as written, against the truth
        assert ("lines across frames:" in result.output) == (name == "across")
        assert all(("across_frames" in row) == (name == "across") for row in rows)
    counted = sum(row["across_frames"] for row in rows)
    assert counted > 0 and f"lines across frames: {counted} of the" in result.output
    assert scores["across"]["precision"] >= 0.95
    assert scores["across"]["completeness"] >= scores["default"]["completeness"]
