"""What a new user tries first: every example in ``accum COMMAND --help`` runs as written, and the
.rrd files of accumulate and view hold what they should (read back with the Rerun SDK)."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from click.testing import CliRunner

from accumcli.cli import main

from .test_visualize import read_rrd

ROOT = Path(__file__).resolve().parent.parent
ORDER = ["simulate", "info", "extract", "accumulate", "eval", "track", "view", "batch"]


def examples(command: str) -> list[str]:
    """The command lines under the "Example(s):" heading of a command's help."""
    text = CliRunner().invoke(main, [command, "--help"], terminal_width=200).output
    found, inside = [], False
    for line in text.splitlines():
        if re.match(r"\s*Examples?:", line):
            inside = True
        elif inside and re.match(r"\s+accum ", line):
            found.append(line.strip())
        elif inside and line.strip():
            inside = False
    return found


def test_every_command_has_an_example():
    for command in ORDER:
        assert examples(command), f"accum {command} --help has no example"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    """A folder like a fresh clone's: the sample data and an out/ folder."""
    root = tmp_path_factory.mktemp("clone")
    (root / "sample_data").symlink_to(ROOT / "sample_data")
    (root / "out").mkdir()
    return root


def test_help_examples_run_as_written(workspace, monkeypatch):
    monkeypatch.chdir(workspace)
    runner = CliRunner()
    for command in ORDER:
        for example in examples(command):
            if "recordings/*.mcap" in example:
                continue   # the form for the user's own folder of recordings
            args = shlex.split(example)[1:]
            result = runner.invoke(main, args)
            assert result.exit_code == 0, f"{example}\n{result.output}"
    accumulate_paths, accumulate_frames = read_rrd(workspace / "out" / "run.rrd")
    assert {"world/camera/image", "world/camera/image/segments", "world/frame_segments", "world/model/accepted",
            "world/model/tentative", "stats/size", "stats/accepted", "stats/confirmed", "stats/new",
            "stats/pruned"} <= accumulate_paths
    assert accumulate_frames == 36
    view_paths, view_frames = read_rrd(workspace / "out" / "view.rrd")
    assert {"world/camera", "world/camera/image", "images/right", "world/model/model/accepted",
            "world/trajectory"} <= view_paths
    assert view_frames == 36
    assert (workspace / "out" / "model.png").stat().st_size > 5000


def test_readme_commands_run_as_written(tmp_path, monkeypatch):
    (tmp_path / "sample_data").symlink_to(ROOT / "sample_data")
    (tmp_path / "out").mkdir()
    monkeypatch.chdir(tmp_path)
    commands = [line.strip() for line in (ROOT / "README.md").read_text().splitlines()
                if line.startswith("    accum ")]
    assert len(commands) >= 8
    for command in commands:
        result = CliRunner().invoke(main, shlex.split(command)[1:])
        assert result.exit_code == 0, f"{command}\n{result.output}"
    assert (tmp_path / "out" / "model.ply").exists() and (tmp_path / "out" / "view.rrd").exists()
