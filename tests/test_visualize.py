"""Rerun logging (accumcli.visualize): log synthetic frames to an .rrd and read it back
with the SDK's own reader. Never spawns or connects to a viewer."""

from __future__ import annotations

import sys

import cv2
import numpy as np
import pytest
from rerun.chunk import RrdReader

from accumcli import visualize
from accumcli.accumulate import StepStats
from accumcli.errors import AccumError
from accumcli.geometry import invert, transform_points
from accumcli.outputs import OutputSet
from accumcli.pipeline import AccumulationStep
from accumcli.visualize import RerunLog

from .test_render import cube_model, frame_and_extraction


def read_rrd(path, timeline: str = "frame") -> tuple[set[str], int]:
    """(entity paths without the leading "/", number of distinct times on ``timeline``) of the
    first recording in the .rrd at ``path``."""
    paths, times = set(), set()
    for chunk in RrdReader(path).stream():
        paths.add(chunk.entity_path.lstrip("/"))
        if timeline in chunk.timeline_names:
            times.update(chunk.to_record_batch().column(timeline).to_pylist())
    return paths, len(times)


def rrd_column(path, entity: str, component: str) -> list:
    """Every row of ``component`` (e.g. "Scalars:scalars") logged on ``entity``, in row order."""
    rows = []
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        if chunk.entity_path.lstrip("/") == entity and component in batch.schema.names:
            rows += batch.column(component).to_pylist()
    return rows


def accumulation_steps(n: int):
    """(step, model, row) of ``n`` synthetic frames: a cube whose confidence grows frame by frame."""
    model = cube_model()
    for i in range(n):
        frame, result = frame_and_extraction(i, model)
        stats = StepStats(observed=len(model), confirmed=10 * i, missed=0, new=len(model) - 10 * i, pruned=i,
                          merged=0, size=len(model), accepted=int(model.accepted.sum()))
        step = AccumulationStep(frame, result, frame.T_camera_object, stats)
        row = {"frame_index": i, "timestamp_ns": frame.timestamp_ns, **stats.__dict__,
               "precision": 0.9, "completeness": 0.1 * i, "background": float("nan")}
        yield step, model, row


def test_accumulation_rrd(tmp_path):
    path = tmp_path / "run.rrd"
    log = RerunLog("accum test", rrd=str(path), kind="accumulate")
    for step, model, row in accumulation_steps(3):
        log.accumulation(step, model, row)
    log.close()
    paths, frames = read_rrd(path)
    expected = {"world", "world/camera", "world/camera/image", "world/camera/image/segments", "images/right",
                "images/right/segments", "world/frame_segments", "world/model/accepted", "world/model/tentative",
                "stats/size", "stats/accepted", "stats/confirmed", "stats/new", "stats/pruned", "stats/precision",
                "stats/completeness"}
    assert expected <= paths, expected - paths
    assert "stats/background" not in paths  # NaN is not logged
    assert "stats/frame_index" not in paths and "stats/missed" not in paths
    assert frames == 3
    assert read_rrd(path, "time")[1] == 3
    assert [v[0] for v in rrd_column(path, "stats/confirmed", "Scalars:scalars")] == [0.0, 10.0, 20.0]
    # The camera pose is the inverse of T_camera_object: world is the object frame.
    translations = rrd_column(path, "world/camera", "Transform3D:translation")
    assert len(translations) == 3
    step = next(accumulation_steps(1))[0]
    assert np.allclose(translations[0][0], invert(step.T_camera_object)[:3, 3], atol=1e-6)


def test_frame_segments_are_in_world(tmp_path):
    path = tmp_path / "one.rrd"
    log = RerunLog("accum test", rrd=str(path), kind="accumulate")
    step, model, row = next(accumulation_steps(1))
    log.accumulation(step, model, row)
    log.close()
    strips = rrd_column(path, "world/frame_segments", "LineStrips3D:strips")[0]
    # Frame segments (camera frame) mapped back into the object frame land on the model.
    world = np.array(strips, float).reshape(-1, 3)
    assert np.allclose(world, model.endpoints().reshape(-1, 3), atol=1e-5)
    accepted = rrd_column(path, "world/model/accepted", "LineStrips3D:strips")[0]
    tentative = rrd_column(path, "world/model/tentative", "LineStrips3D:strips")[0]
    assert len(accepted) == model.accepted.sum() and len(tentative) == (~model.accepted).sum()


def test_extraction_rrd(tmp_path):
    path = tmp_path / "extract.rrd"
    log = RerunLog("accum test", rrd=str(path), kind="extract")
    model = cube_model()
    for i in range(2):
        log.extraction(*frame_and_extraction(i, model))
    log.close()
    paths, frames = read_rrd(path)
    expected = {"world", "world/camera", "world/camera/image", "world/camera/image/segments", "images/right",
                "images/right/segments", "world/frame_segments"}
    assert expected <= paths, expected - paths
    assert not any(p.startswith(("stats", "world/model")) for p in paths)
    assert frames == 2
    # Left 2D segments: the matched ones and the one unmatched in two colours, shifted to Rerun's pixel centres.
    frame, result = frame_and_extraction(0, model)
    colors = rrd_column(path, "world/camera/image/segments", "LineStrips2D:colors")[0]
    assert len(set(colors)) == 2 and colors.count(colors[-1]) == 1
    strips = rrd_column(path, "world/camera/image/segments", "LineStrips2D:strips")[0]
    assert np.allclose(np.array(strips[0]), result.left.endpoints()[0] + 0.5, atol=1e-4)
    # World is the left camera frame: the 3D segments are logged as extracted.
    world = np.array(rrd_column(path, "world/frame_segments", "LineStrips3D:strips")[0]).reshape(-1, 3)
    assert np.allclose(world, transform_points(np.eye(4), result.segments.endpoints().reshape(-1, 3)), atol=1e-5)


def blueprint_views(path) -> list[str]:
    """Sorted class identifiers ("2D", "3D", "TimeSeries", ...) of the views in the .rrd's blueprint."""
    reader = RrdReader(path)
    (store,) = reader.blueprints()
    views = []
    for chunk in reader.stream(store=store):
        batch = chunk.to_record_batch()
        if "ViewBlueprint:class_identifier" in batch.schema.names:
            views += [row[0] for row in batch.column("ViewBlueprint:class_identifier").to_pylist()]
    return sorted(views)


@pytest.mark.parametrize("kind, images, views", [("accumulate", True, ["2D", "2D", "3D", "TimeSeries"]),
                                                 ("track", True, ["2D", "2D", "3D", "TimeSeries"]),
                                                 ("extract", True, ["2D", "2D", "3D"]),
                                                 ("view", True, ["2D", "2D", "3D"]), ("view", False, ["3D"])])
def test_blueprint_is_saved(tmp_path, kind, images, views):
    """Both images wherever they are logged; no empty image panel where none is (a view without a recording)."""
    path = tmp_path / "bp.rrd"
    RerunLog("accum test", rrd=str(path), kind=kind, images=images).close()
    assert len(RrdReader(path).recordings()) == 1
    assert blueprint_views(path) == views


def test_exactly_one_sink(tmp_path):
    with pytest.raises(ValueError):
        RerunLog("accum test", kind="view")
    with pytest.raises(ValueError):
        RerunLog("accum test", rrd=str(tmp_path / "x.rrd"), connect="rerun+http://127.0.0.1:9/proxy")
    with pytest.raises(ValueError):
        RerunLog("accum test", rrd=str(tmp_path / "x.rrd"), kind="nonsense")


def test_connect_without_a_viewer_is_one_error_before_the_work():
    import socket

    with socket.socket() as probe:   # a port nothing listens on once closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    with pytest.raises(AccumError, match=rf"no Rerun viewer answers at 127.0.0.1:{port} .*--rrd"):
        RerunLog("accum test", connect=f"rerun+http://127.0.0.1:{port}/proxy")
    with pytest.raises(AccumError, match="expected a Rerun viewer URL such as rerun"):
        RerunLog("accum test", connect="notaurl")


def test_trajectory_and_scalars(tmp_path):
    path = tmp_path / "track.rrd"
    log = RerunLog("accum test", rrd=str(path), kind="track")
    for i in range(4):
        log.set_frame(i, 10 ** 9 + i)
        log.scalars({"inliers": i, "ok": True, "status": "tracking", "error_mm": np.float32(0.5)})
    log.trajectory(np.arange(12.0).reshape(4, 3))
    log.close()
    paths, frames = read_rrd(path)
    assert {"stats/inliers", "stats/error_mm", "world/trajectory"} <= paths
    assert "stats/ok" not in paths and "stats/status" not in paths
    assert frames == 4
    assert np.allclose(rrd_column(path, "world/trajectory", "LineStrips3D:strips")[0], np.arange(12.0).reshape(4, 3))


def test_images_are_jpeg(tmp_path):
    path = tmp_path / "img.rrd"
    with RerunLog("accum test", rrd=str(path), kind="extract") as log:
        frame, result = frame_and_extraction(0, cube_model())
        log.extraction(frame, result)
    for entity, image in (("world/camera/image", frame.left), ("images/right", frame.right)):
        assert rrd_column(path, entity, "EncodedImage:media_type") == [["image/jpeg"]]
        blob = np.array(rrd_column(path, entity, "EncodedImage:blob")[0][0], np.uint8)
        decoded = cv2.imdecode(blob, cv2.IMREAD_UNCHANGED)
        assert decoded.shape == image.shape
        assert np.abs(decoded.astype(int) - image).mean() < 8  # JPEG quality 85 on a small test image


def test_rrd_is_part_of_an_output_set(tmp_path):
    target = tmp_path / "run.rrd"
    with pytest.raises(KeyboardInterrupt):
        with OutputSet([target]) as out:
            log = RerunLog("accum test", rrd=out.path(target), kind="view")
            log.close()
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []  # no 0-byte run.rrd, no temp
    with OutputSet([target]) as out, RerunLog("accum test", rrd=out.path(target), kind="view"):
        pass
    assert len(RrdReader(target).recordings()) == 1


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the display check is for Linux")
def test_spawn_without_a_display(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(visualize.rr, "spawn", lambda **kw: pytest.fail("must not try to spawn"))
    with pytest.raises(AccumError, match=r"^cannot start the Rerun viewer: no display .*; use --rrd"):
        RerunLog("accum test", spawn=True)


def test_spawn_without_a_viewer(monkeypatch, tmp_path):
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(visualize.sys, "executable", str(tmp_path / "python"))
    monkeypatch.setattr(visualize.shutil, "which", lambda name: None)
    with pytest.raises(AccumError, match=r"^cannot start the Rerun viewer: no 'rerun' executable .*; use --rrd"):
        RerunLog("accum test", spawn=True)


def test_spawn_failure_is_one_line(monkeypatch, tmp_path):
    viewer = tmp_path / "rerun"
    viewer.write_text("#!/bin/sh\n")
    viewer.chmod(0o755)
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setattr(visualize.sys, "executable", str(tmp_path / "python"))
    calls = []

    def failing_spawn(**kwargs):
        calls.append(kwargs["executable_path"])
        raise RuntimeError("viewer exited")

    monkeypatch.setattr(visualize.rr, "spawn", failing_spawn)
    with pytest.raises(AccumError, match=r"^cannot start the Rerun viewer \(RuntimeError: viewer exited\); use --rrd$"):
        RerunLog("accum test", spawn=True)
    assert calls == [str(viewer)]


def test_view_shows_a_trackers_failure_and_every_model(small_recording, tmp_path):
    """A poses file's lost frame clears the model (not the recording's pose in its place) and says
    why on pose_source; the trajectory has one point per placed frame; two models named alike both show."""
    import json
    import shutil

    from accumcli.runs import accumulate_recording, view

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    accumulate_recording(small_recording, [str(tmp_path / "a" / "model.json")])
    shutil.copy(tmp_path / "a" / "model.json", tmp_path / "b" / "model.json")
    truth = json.loads(open(small_recording.replace(".mcap", ".truth.json")).read())
    poses = [{**p, "status": "tracked"} for p in truth["poses"][:6]]
    poses[2] = {"timestamp_ns": poses[2]["timestamp_ns"], "translation": None, "rotation_xyzw": None,
                "status": "lost", "reason": "coverage 0.10 in both images (needs 0.45)"}
    track = tmp_path / "poses.json"
    track.write_text(json.dumps({"format": "accum.poses/1", "parent_frame_id": "camera_left",
                                 "child_frame_id": "gripper", "poses": poses}))
    rrd = tmp_path / "v.rrd"
    truth_path = small_recording.replace(".mcap", ".truth.json")
    view([small_recording, str(tmp_path / "a" / "model.json"), str(tmp_path / "b" / "model.json"), str(track),
          truth_path], rrd=str(rrd))
    paths, frames = read_rrd(str(rrd))
    assert {"world/model/model/accepted", "world/model/model_2/accepted", "world/truth"} <= paths
    assert not any(p.startswith("world/model/truth") for p in paths)   # the truth is not drawn as a model
    assert rrd_column(str(rrd), "world/truth", "LineStrips3D:colors")[0][0] == \
        int.from_bytes(bytes([*visualize.TRUTH, 255]), "big")
    # at the truth's own poses, in every frame: a lost or wrong pose shows against it
    assert len(rrd_column(str(rrd), "world/truth", "LineStrips3D:strips")) == frames
    sources = [row[0] for row in rrd_column(str(rrd), "pose_source", "TextLog:text")]
    assert sources[:3] == ["poses.json: tracked", "poses.json: tracked",
                           "poses.json: lost (coverage 0.10 in both images (needs 0.45))"]
    assert sources[6:] == ["recorded"] * (frames - 6)   # beyond the poses file: the recording's poses
    strip = rrd_column(str(rrd), "world/trajectory", "LineStrips3D:strips")[-1][0]
    assert len(strip) == frames - 1   # every frame but the lost one, once


def test_view_without_a_recording_places_the_models_at_the_poses(small_recording, tmp_path):
    """A model with a poses file: world is the camera frame, the model drawn at each tracked pose (it
    stood at the origin while the trajectory was in the camera frame); a model alone: the object frame."""
    import json

    from accumcli.geometry import transform_from_quat
    from accumcli.model_io import read_model
    from accumcli.runs import accumulate_recording, view

    model_path = tmp_path / "model.json"
    accumulate_recording(small_recording, [str(model_path)])
    model = read_model(model_path)
    truth = json.loads(open(small_recording.replace(".mcap", ".truth.json")).read())
    track = tmp_path / "poses.json"
    track.write_text(json.dumps({"format": "accum.poses/1", "parent_frame_id": "camera_left",
                                 "child_frame_id": "gripper", "poses": truth["poses"]}))
    rrd = tmp_path / "v.rrd"
    view([str(model_path), str(track)], rrd=str(rrd))
    paths, frames = read_rrd(str(rrd))
    assert frames == len(truth["poses"]) and "world/camera/image" not in paths
    strips = rrd_column(str(rrd), "world/model/model/accepted", "LineStrips3D:strips")
    drawn = np.array(strips[0], float).reshape(-1, 3).mean(axis=0)
    T = transform_from_quat(truth["poses"][0]["translation"], truth["poses"][0]["rotation_xyzw"])
    expected = transform_points(T, model.select(model.accepted).endpoints().reshape(-1, 3)).mean(axis=0)
    assert np.allclose(drawn, expected, atol=1e-5)
    trajectory = np.array(rrd_column(str(rrd), "world/trajectory", "LineStrips3D:strips")[-1][0])
    assert np.allclose(trajectory[0], T[:3, 3], atol=1e-6)   # in the same frame as the model
    alone = tmp_path / "m.rrd"
    view([str(model_path)], rrd=str(alone))
    first = np.array(rrd_column(str(alone), "world/model/model/accepted", "LineStrips3D:strips")[0], float)
    at_origin = model.select(model.accepted).endpoints().reshape(-1, 3).mean(axis=0)
    assert np.allclose(first.reshape(-1, 3).mean(axis=0), at_origin, atol=1e-5)


def test_a_full_disk_under_the_rrd_is_one_error_line(tmp_path, monkeypatch):
    """Rerun's file writer says only "File-writer thread shut down prematurely" (a traceback before)."""
    import os
    from types import SimpleNamespace

    log = RerunLog("accum test", rrd=str(tmp_path / "r.rrd"), kind="view")

    def broken_flush():
        raise RuntimeError("File-writer thread shut down prematurely")

    monkeypatch.setattr(log.rec, "flush", broken_flush)
    monkeypatch.setattr(os, "statvfs", lambda folder: SimpleNamespace(f_bavail=3, f_frsize=4096))
    with pytest.raises(AccumError, match=f"no space left on device writing the Rerun recording in {tmp_path}"):
        log.close()
    monkeypatch.setattr(os, "statvfs", lambda folder: SimpleNamespace(f_bavail=1 << 30, f_frsize=4096))
    with pytest.raises(AccumError, match=r"Rerun could not write the recording .*shut down prematurely"):
        log.close()


def test_view_places_a_model_in_its_own_frame_and_frames_selects_a_frames_files_lines(small_recording, tmp_path):
    """The chessboard with its model (frame 'board') and no --object-frame: the model is placed in
    every frame (it was not shown, and nothing said); --frames 1:3 shows the frames file's lines of
    frames 1 and 2 only (it showed every line)."""
    from pathlib import Path

    from accumcli.model_io import read_truth, write_model
    from accumcli.runs import FrameRange, extract_recording, view
    from accumcli.segments import Segments

    board = Path(__file__).resolve().parent.parent / "sample_data" / "chessboard"
    truth = read_truth(str(board / "chessboard.truth.json"))
    length = np.linalg.norm(truth.b - truth.a, axis=1)
    model = Segments("board", (truth.a + truth.b) / 2, (truth.b - truth.a) / length[:, None], length,
                     np.ones(len(length)), np.full(len(length), 3, np.int64))
    write_model(tmp_path / "board.json", model)
    rrd = tmp_path / "board.rrd"
    view([str(board / "chessboard.mcap"), str(tmp_path / "board.json")], rrd=str(rrd), object_frame_of_model=True,
         frames=FrameRange(0, 3))
    assert len(rrd_column(str(rrd), "world/model/board/accepted", "LineStrips3D:strips")) == 3
    other = tmp_path / "other.png"   # a recording without the models' frame keeps its own (the box sample)
    view([small_recording, str(tmp_path / "board.json")], png=str(other), object_frame_of_model=True)
    assert other.stat().st_size > 1000
    frames_file = tmp_path / "frames.jsonl"
    extract_recording(small_recording, str(frames_file), frames=FrameRange(0, 4))
    rrd = tmp_path / "frames.rrd"
    view([small_recording, str(frames_file)], rrd=str(rrd), frames=FrameRange(1, 3))
    assert len(rrd_column(str(rrd), "world/frame_segments", "LineStrips3D:strips")) == 2


@pytest.mark.parametrize("text, count, middle", [("", 36, 18), ("0:6", 36, 3), ("10:", 36, 23), ("30:99", 36, 33),
                                                 ("40:50", 36, 40)])
def test_the_picture_shows_the_middle_of_the_frames_selected(text, count, middle):
    """``view --png`` without --png-frame draws the middle frame of --frames (it drew the recording's middle);
    a range past the end names its first frame, which the view then reports missing."""
    from accumcli.runs.base import FrameRange
    from accumcli.runs.viewing import middle_frame

    assert middle_frame(FrameRange.parse(text) if text else FrameRange(), count) == middle
