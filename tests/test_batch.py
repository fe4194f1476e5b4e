"""accum batch: many recordings, one row each, failures in their rows, re-runs skip, Ray."""

from __future__ import annotations

import shutil

import pytest
from click.testing import CliRunner

from accumcli.batch import BatchOptions, run_batch
from accumcli.cli import main
from accumcli.errors import InputError
from accumcli.runs import FrameRange


@pytest.fixture(scope="module")
def recordings(tmp_path_factory, small_recording):
    """Two copies of the small recording (with truth) and a broken file."""
    folder = tmp_path_factory.mktemp("batch_in")
    paths = []
    for name in ("a", "b"):
        shutil.copy(small_recording, folder / f"{name}.mcap")
        shutil.copy(small_recording.replace(".mcap", ".truth.json"), folder / f"{name}.truth.json")
        paths.append(str(folder / f"{name}.mcap"))
    (folder / "broken.mcap").write_bytes(b"\x89MCAP0\r\nnot really")
    return paths + [str(folder / "broken.mcap")]


OPTIONS = BatchOptions(frames=FrameRange(0, 3), truth_from_sidecar=True)


def test_one_row_per_recording_and_failures_stay_in_their_row(recordings, tmp_path):
    result = run_batch(recordings, tmp_path, OPTIONS, workers=2)
    assert [r["status"] for r in result.rows][:2] == ["ok", "ok"]
    assert result.rows[2]["status"].startswith("error: ") and "broken.mcap" in result.rows[2]["status"]
    assert result.rows[0]["frames"] == 3 and result.rows[0]["precision"] > 0.8
    for name in ("a", "b"):
        assert {p.name for p in (tmp_path / name).iterdir()} >= {"model.json", "model.ply", "eval.json", "done.json"}
    assert not (tmp_path / "broken").exists()   # no empty folder for a recording that failed
    lines = (tmp_path / "summary.csv").read_text().splitlines()
    assert lines[0].startswith("recording,frames,segments,accepted,precision") and len(lines) == 4
    again = run_batch(recordings, tmp_path, OPTIONS, workers=1)
    assert [r.get("skipped", False) for r in again.rows] == [True, True, False]
    assert (tmp_path / "summary.csv").read_text().splitlines() == lines


def test_one_and_two_workers_and_ray_give_the_same_summary(recordings, tmp_path, caplog):
    """The same summary whatever runs the tasks; a task's warnings reach the user from Ray's workers too (their
    log stayed in the worker)."""
    pytest.importorskip("ray")
    from . import helpers

    unpaired = helpers.write(tmp_path / "unpaired.mcap", unpaired_right=(1,))   # warns: an image with no partner
    summaries = []
    for name, kwargs in (("one", dict(workers=1)), ("two", dict(workers=2)), ("ray", dict(ray_address="local"))):
        caplog.clear()
        run_batch([*recordings[:2], unpaired], tmp_path / name, OPTIONS, **kwargs)
        summaries.append((tmp_path / name / "summary.csv").read_text())
    assert summaries[0] == summaries[1] == summaries[2]
    assert "has no partner" in caplog.text   # the Ray run's
    with pytest.raises(InputError, match="with --ray the cluster schedules"):   # it did nothing, silently
        run_batch(recordings[:2], tmp_path / "both", OPTIONS, workers=2, ray_address="local")


def test_batch_command_prints_the_table_and_exits_1_when_any_fails(recordings, tmp_path):
    runner = CliRunner()
    ok = runner.invoke(main, ["batch", *recordings[:2], "-o", str(tmp_path / "o"), "--frames", "0:2", "--workers", "1"])
    assert ok.exit_code == 0, ok.output
    assert "recording" in ok.output.splitlines()[0] and "0 failed" in ok.output
    some = runner.invoke(main, ["batch", *recordings, "-o", str(tmp_path / "o"), "--frames", "0:2", "--workers", "1"])
    assert some.exit_code == 1 and "1 failed" in some.output
    assert some.output.strip().splitlines()[-1] == (f"error: 1 of 3 recordings failed (see the status column of "
                                                    f"{tmp_path / 'o' / 'summary.csv'}); the others' outputs are written")
    bad = runner.invoke(main, ["batch", recordings[2], "-o", str(tmp_path / "p")])
    assert bad.exit_code == 1 and "every recording failed" in bad.output


def test_an_output_folder_that_cannot_be_made_is_one_error(recordings, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = CliRunner().invoke(main, ["batch", recordings[0], "-o", str(blocker / "batch")])
    assert result.exit_code == 1 and "Traceback" not in result.output
    assert result.output.strip().splitlines()[-1].startswith(f"error: {blocker / 'batch'}: cannot create the output folder")


def test_batch_box_reaches_each_run_and_its_outputs(recordings, tmp_path):
    """--box is an accumulation option like the others: each row's run drops what lies outside it (a box
    around nothing fails every row, naming the box), and a re-run with another box is not skipped."""
    runner = CliRunner()
    args = ["batch", *recordings[:1], "-o", str(tmp_path / "o"), "--frames", "0:3", "--workers", "1"]
    assert runner.invoke(main, args + ["--box", "-1:1,-1:1,-1:1"]).exit_code == 0
    far = runner.invoke(main, args + ["--box", "9:10,9:10,9:10"])
    assert far.exit_code == 1 and "every recording failed" in far.output
    assert "outside --box" in (tmp_path / "o" / "summary.csv").read_text()


def test_a_rerun_with_other_options_leaves_no_output_of_the_earlier_one(recordings, tmp_path):
    """A re-run without --track and without truth must not leave the earlier run's poses.json and
    eval.json beside its new model (a script would read figures of another model)."""
    first = BatchOptions(frames=FrameRange(0, 3), track=True, truth_from_sidecar=True)
    run_batch(recordings[:1], tmp_path, first, workers=1)
    assert {"poses.json", "eval.json"} <= {p.name for p in (tmp_path / "a").iterdir()}
    run_batch(recordings[:1], tmp_path, BatchOptions(frames=FrameRange(0, 4)), workers=1)
    assert {p.name for p in (tmp_path / "a").iterdir()} == {"model.json", "model.ply", "done.json"}


def test_a_batch_folder_named_dash_is_a_folder(recordings, tmp_path, monkeypatch):
    """-o - is stdout for a file output, but batch writes a folder: '-' stays its name."""
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["batch", *recordings[:1], "-o", "-", "--frames", "0:2", "--workers", "1"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "-" / "summary.csv").exists()


def test_the_truth_sidecar_of_a_rosbag2_folder_is_beside_it():
    """NAME.truth.json beside NAME.mcap, and beside a rosbag2 folder NAME (it has no suffix: its
    sidecar was looked for as '.truth.json')."""
    from pathlib import Path

    from accumcli.batch import _sidecar

    assert _sidecar(Path("data/box.mcap")) == Path("data/box.truth.json")
    assert _sidecar(Path("data/box_bag")) == Path("data/box_bag.truth.json")
    assert _sidecar(Path("data/run.2.db3")) == Path("data/run.2.truth.json")


def test_the_truth_sidecar_of_a_dotted_rosbag2_folder_keeps_its_whole_name(tmp_path):
    from accumcli.batch import _sidecar

    (tmp_path / "run.2").mkdir()
    assert _sidecar(tmp_path / "run.2") == tmp_path / "run.2.truth.json"


def test_a_bag_folder_rewritten_in_place_is_not_up_to_date(tmp_path):
    """A rosbag2 folder's stamp is its files' (a bag file rewritten in place left the folder's own size and
    time as they were, and batch skipped it as up to date)."""
    from accumcli.batch import _inputs_stamp

    bag = tmp_path / "run"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    (bag / "run_0.db3").write_bytes(b"first")
    before = _inputs_stamp(bag, OPTIONS)
    (bag / "run_0.db3").write_bytes(b"second, longer")
    assert _inputs_stamp(bag, OPTIONS) != before
