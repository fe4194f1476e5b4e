"""The library as an integrator calls it: its own checks of the arguments (the CLI's options are not the only
gate)."""

from __future__ import annotations

import numpy as np
import pytest

from accumcli.errors import InputError
from accumcli.evaluate import Tolerances
from accumcli.model_io import checked_segments
from accumcli.pipeline import AccumulateParams
from accumcli.runs import FrameRange, RecordingOptions
from accumcli.segments import Segments


def test_the_library_refuses_bad_arguments_as_the_cli_does():
    """A library caller's bad values are InputErrors before any work (the CLI's options checked them; the
    library ran with them: an unknown motion silently skipped the pose repair, a box in millimetres kept
    everything, a NaN tolerance scored every model 0)."""
    for bad in (dict(motion="Tracked"), dict(box=((0, 100), (0, 100), (0, 100))), dict(box=(0, 1)),
                dict(box=((0.1, 0), (0, 0.1), (0, 0.1)))):
        with pytest.raises(InputError):
            AccumulateParams(**bad)
    assert AccumulateParams(box=[[0, 0.1], [0, 0.1], [-0.1, 0]]).box == ((0.0, 0.1), (0.0, 0.1), (-0.1, 0.0))
    for bad in (dict(position_tol=float("nan")), dict(angle_tol_deg=-1.0), dict(min_seen=0)):
        with pytest.raises(InputError):
            Tolerances(**bad)
    for bad in (dict(tolerance_ns=-5), dict(tolerance_ns=float("nan")), dict(time_offset_ns="1ms"),
                dict(object_frame="")):
        with pytest.raises(InputError):
            RecordingOptions(**bad)
    assert FrameRange(np.int64(2), np.int64(8)) == FrameRange(2, 8)
    tripled = Segments("o", np.zeros((2, 3)), np.array([[3.0, 0, 0], [0, 0, -2.0]]), np.array([0.01, 0.02]),
                       np.ones(2), np.ones(2, np.int64))
    assert np.allclose(checked_segments(tripled, "m").directions, [[1, 0, 0], [0, 0, -1]])
    with pytest.raises(InputError, match="positive number of metres"):
        checked_segments(Segments("o", np.zeros((1, 3)), np.ones((1, 3)), np.array([-0.01]), np.ones(1),
                                  np.ones(1, np.int64)), "m")
    with pytest.raises(InputError, match="disagree in length"):
        checked_segments(Segments("o", np.zeros((2, 3)), np.ones((1, 3)), np.ones(2), np.ones(2),
                                  np.ones(2, np.int64)), "m")


def test_the_runs_refuse_an_output_that_names_no_format(small_recording, tmp_path):
    """The CLI refused -o model.txt; the library wrote it as JSON without a word. Now both refuse it."""
    from accumcli.runs import accumulate_recording, track_recording

    with pytest.raises(InputError, match=r"expected a \.json, \.ply or \.mcap file, found '.*model\.txt'"):
        accumulate_recording(small_recording, [str(tmp_path / "model.txt")])
    with pytest.raises(InputError, match=r"expected a \.json, \.tum or \.mcap file, found the standard output"):
        track_recording(str(tmp_path / "model.json"), small_recording, ["-"])
