"""The model as Foxglove sees 3D things: a ``foxglove.SceneUpdate`` of line primitives in the object
frame, one per stereo frame as the model grows, plus the model's counts over time as JSON messages
that Foxglove plots. Opened beside the recording (whose /tf carries the object frame), the model
moves with the object.

Colour by confidence, as in the PLY (``model_io.confidence_rgb``): yellow (0.5) to green (1) for
accepted segments; tentative ones, light grey and thin, only when asked for.
"""

from __future__ import annotations

import numpy as np
from foxglove_schemas_protobuf.Color_pb2 import Color
from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
from foxglove_schemas_protobuf.Point3_pb2 import Point3
from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

from .model_io import confidence_rgb
from .segments import Segments

SCENE_TOPIC = "/accum/model"
STATS_TOPIC = "/accum/model_stats"
STATS_SCHEMA = {"type": "object", "title": "accum.ModelStats",
                "properties": {k: {"type": "integer"} for k in ("frame_index", "size", "accepted", "observed",
                                                                  "confirmed", "missed", "new", "pruned", "merged")}}


def _lines(segments: Segments, rgb: np.ndarray, thickness: float) -> LinePrimitive:
    """One LINE_LIST primitive: two points per segment, one colour per point (RGB 0..255)."""
    line = LinePrimitive(type=LinePrimitive.LINE_LIST, thickness=thickness, scale_invariant=True)
    line.pose.orientation.w = 1.0
    ends = segments.endpoints().reshape(-1, 3)
    line.points.extend(Point3(x=float(x), y=float(y), z=float(z)) for x, y, z in ends)
    colours = np.repeat(np.asarray(rgb, float) / 255.0, 2, axis=0)
    line.colors.extend(Color(r=r, g=g, b=b, a=1.0) for r, g, b in colours)
    return line


def model_scene(model: Segments, t_ns: int, tentative: bool = False, entity_id: str = "accum_model") -> SceneUpdate:
    """The model (object frame ``model.frame_id``) as a SceneUpdate at ``t_ns``: accepted segments
    coloured by confidence (2 px), tentative ones light grey (1 px) if ``tentative``. The entity is
    frame-locked, so it follows the object frame's transforms."""
    entity = SceneEntity(frame_id=model.frame_id, id=entity_id, frame_locked=True)
    entity.timestamp.FromNanoseconds(int(t_ns))
    accepted = model.select(model.accepted)
    if len(accepted):
        entity.lines.append(_lines(accepted, confidence_rgb(accepted.confidence), 2.0))
    if tentative:
        rest = model.select(~model.accepted)
        if len(rest):
            entity.lines.append(_lines(rest, np.full((len(rest), 3), 200.0), 1.0))
    return SceneUpdate(entities=[entity])


class ModelMcap:
    """Writes the model of every frame and its counts to an MCAP (a ``RecordingWriter``)."""

    def __init__(self, writer, tentative: bool = False):
        self.writer = writer
        self.tentative = tentative

    def frame(self, model: Segments, t_ns: int, counts: dict) -> None:
        self.writer.message(SCENE_TOPIC, model_scene(model, t_ns, self.tentative), t_ns)
        doc = {k: int(v) for k, v in counts.items() if k in STATS_SCHEMA["properties"]}
        doc["accepted"] = int(model.accepted.sum())
        self.writer.json_message(STATS_TOPIC, STATS_SCHEMA["title"], STATS_SCHEMA, doc, t_ns)
