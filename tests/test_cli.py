"""The command line: one error line and exit 1 for user errors; help and version."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from accumcli.cli import main

from .test_recording import broken_files

COMMANDS_ON_RECORDINGS = [["info"]]


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
    result = run(*command, path, *(["-o", tmp_path / "out.json"] if command[0] != "info" else []))
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert lines[-1].startswith("error: ") and message in lines[-1] and str(path) in lines[-1]
    assert "Traceback" not in result.output


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


def test_simulate_rejects_bad_options(tmp_path):
    result = run("simulate", "-o", tmp_path / "x.mcap", "--pose-noise", "abc")
    assert result.exit_code == 2 and "expected DEG,MM" in result.output
    result = run("simulate", "-o", tmp_path / "missing" / "x.mcap", "--frames", "1", "--size", "64x48")
    assert result.exit_code == 1 and "does not exist" in result.output
