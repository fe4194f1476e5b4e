"""The model for Foxglove (accumcli.foxglove_scene): accumulate -o model.mcap, decoded with
Foxglove's own protobuf schemas."""

from __future__ import annotations

import json

import numpy as np
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
from mcap.reader import make_reader

from accumcli.model_io import read_model
from accumcli.runs import FrameRange, accumulate_recording


def test_model_mcap_holds_the_growing_model_in_the_object_frame(small_recording, tmp_path):
    model_mcap, model_json = tmp_path / "m.mcap", tmp_path / "m.json"
    result = accumulate_recording(small_recording, [str(model_mcap), str(model_json)], frames=FrameRange(0, 4))
    with open(model_mcap, "rb") as f:
        reader = make_reader(f)
        scenes, stats = [], []
        for schema, channel, message in reader.iter_messages():
            if channel.topic == "/accum/model":
                assert schema.name == "foxglove.SceneUpdate" and schema.encoding == "protobuf"
                scenes.append((message.log_time, SceneUpdate.FromString(message.data)))
            elif channel.topic == "/accum/model_stats":
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
                stats.append(json.loads(message.data))
    assert len(scenes) == len(stats) == 4
    assert [t for t, _ in scenes] == [row["timestamp_ns"] for row in result.rows]
    # the counts of the model as written at that frame (twins merged, dominant directions: ``line_model``),
    # which the scene draws, not the running accumulation's of ``result.rows``; both come from one model in
    # ``foxglove_scene``, so the run's own count of the last one is the independent check
    drawn = [len(scene.entities[0].lines[0].points) // 2 if scene.entities[0].lines else 0 for _, scene in scenes]
    assert [s["accepted"] for s in stats] == drawn and drawn[-1] == result.accepted > 0
    assert [s["frame_index"] for s in stats] == [row["frame_index"] for row in result.rows]
    entity = scenes[-1][1].entities[0]
    assert entity.frame_id == "gripper" and entity.frame_locked
    final = read_model(model_json)
    points = np.array([[p.x, p.y, p.z] for p in entity.lines[0].points])
    expected = final.select(final.accepted).endpoints().reshape(-1, 3)
    np.testing.assert_allclose(points, expected, atol=1e-6)   # the JSON rounds
    greens = np.array([c.g for c in entity.lines[0].colors])
    assert len(greens) == len(points) and greens.min() > 0.99   # accepted: yellow (0.5) to green, green full
