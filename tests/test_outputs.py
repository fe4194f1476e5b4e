"""Outputs of a run as a set (accumcli.outputs) and its single-file case (accumcli.atomic)."""

from __future__ import annotations

import builtins
import errno
import os
import signal
import threading
import time

import pytest

from accumcli import outputs
from accumcli.atomic import atomic_open, atomic_path
from accumcli.errors import AccumError
from accumcli.outputs import OutputSet, interrupt_on_sigterm, output_error
from accumcli.recording import RecordingWriter


def names(folder) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_all_appear_together_at_the_end(tmp_path):
    a, b = str(tmp_path / "model.json"), str(tmp_path / "run.rrd")
    with OutputSet([a, b]) as out:
        with out.open(a) as f:
            f.write("new a")
        with open(out.path(b), "wb") as f:
            f.write(b"new b")
        temps = names(tmp_path)
        assert len(temps) == 2 and all(n.startswith(".accum-") and n.endswith(".tmp") and len(n) == 19
                                       for n in temps)
    assert names(tmp_path) == ["model.json", "run.rrd"]
    assert (tmp_path / "model.json").read_text() == "new a" and (tmp_path / "run.rrd").read_bytes() == b"new b"
    assert out.paths == [a, b]


@pytest.mark.parametrize("error", [KeyboardInterrupt, SystemExit, ValueError])
def test_an_exception_keeps_the_previous_files(tmp_path, error):
    a, b = tmp_path / "model.json", tmp_path / "model.ply"
    a.write_text("old a")
    b.write_text("old b")
    with pytest.raises(error):
        with OutputSet([a, b]) as out:
            out.open(a).write("new a")
            out.open(b, "wb").write(b"new b")
            raise error
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert names(tmp_path) == ["model.json", "model.ply"]


def test_outputs_not_handed_out_are_left_alone(tmp_path):
    (tmp_path / "panel.png").write_text("old")
    with OutputSet([tmp_path / "m.json", tmp_path / "panel.png"]) as out:
        out.open(tmp_path / "m.json").write("{}")
        with pytest.raises(KeyError, match="other.json is not an output of this set"):
            out.open(tmp_path / "other.json")
    assert (tmp_path / "panel.png").read_text() == "old" and (tmp_path / "m.json").read_text() == "{}"
    with pytest.raises(RuntimeError, match="the output set is already finished"):
        out.open(tmp_path / "m.json")


@pytest.mark.parametrize("make, message", [
    (lambda d: d / "nope" / "m.json", r"m\.json: the folder .*nope does not exist; create it or write elsewhere$"),
    (lambda d: d, r": is a folder; give a file name$"),
    (lambda d: d / ("x" * 256), r"the file name is 256 bytes, more than the 255 its folder allows; give a shorter"),
])
def test_checked_before_any_work(tmp_path, make, message):
    with pytest.raises(AccumError, match=message):
        OutputSet([tmp_path / "ok.json", make(tmp_path)])
    assert names(tmp_path) == []


def test_given_twice(tmp_path):
    with pytest.raises(AccumError, match="m.json: given twice as an output; give each output once"):
        OutputSet([str(tmp_path / "m.json"), str(tmp_path / "m.json")])
    (tmp_path / "sub").mkdir()
    with pytest.raises(AccumError, match=r"two outputs are the same file"):
        OutputSet([str(tmp_path / "m.json"), str(tmp_path / "." / "sub" / ".." / "m.json")])
    (tmp_path / "real.json").write_text("")
    (tmp_path / "link.json").symlink_to(tmp_path / "real.json")
    with pytest.raises(AccumError, match=r"two outputs are the same file"):
        OutputSet([tmp_path / "real.json", tmp_path / "link.json"])


def test_an_input_is_never_an_output(tmp_path):
    recording = tmp_path / "run.mcap"
    recording.write_bytes(b"recording")
    (tmp_path / "link.mcap").symlink_to(recording)
    for output in (recording, tmp_path / "." / "run.mcap", tmp_path / "link.mcap"):
        with pytest.raises(AccumError, match=r"is also an input of this run .*run\.mcap\); write the output to another file"):
            OutputSet([tmp_path / "model.json", output], inputs=[recording, None])
    assert recording.read_bytes() == b"recording"
    OutputSet([tmp_path / "model.json"], inputs=[recording, tmp_path / "not-there.json"])   # others pass


def test_a_long_name_works(tmp_path):
    target = tmp_path / ("m" * 243 + ".json")
    with atomic_open(target) as f:
        f.write("ok")
    assert len(target.name) == 248 and target.read_text() == "ok"


@pytest.mark.parametrize("code, message", [
    (errno.EACCES, r"m\.json: cannot create a file in .* \(Permission denied\); choose a folder you can write to$"),
    (errno.EROFS, r"m\.json: cannot create a file in .* \(Read-only file system\)"),
    (errno.ENOENT, r"m\.json: cannot create a file in .* \(No such file or directory\)"),   # /proc's answer
])
def test_unwritable_folder_is_refused_up_front(tmp_path, monkeypatch, code, message):
    def refuse(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(outputs.tempfile, "mkstemp", refuse)
    with pytest.raises(AccumError, match=message):
        OutputSet([tmp_path / "m.json"])


def test_full_disk_while_writing(tmp_path, monkeypatch):
    target = tmp_path / "model.json"
    target.write_text("old")
    monkeypatch.setattr(outputs, "open", lambda path, mode, encoding=None: builtins.open("/dev/full", mode),
                        raising=False)
    with pytest.raises(AccumError, match=r"^no space left on device writing .*model\.json; free some space"):
        with OutputSet([target]) as out:
            out.open(target).write("x" * 100_000)
    assert target.read_text() == "old" and names(tmp_path) == ["model.json"]


def test_other_os_errors_are_not_taken_for_output_faults(tmp_path):
    with pytest.raises(PermissionError, match="secret.mcap"):  # reading an input: not ours to rename
        with OutputSet([tmp_path / "m.json"]) as out:
            out.open(tmp_path / "m.json")
            raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "secret.mcap"))
    with pytest.raises(AccumError, match=r"^no space left on device writing .*m\.json; "):
        with OutputSet([tmp_path / "m.json"]) as out:
            out.path(tmp_path / "m.json")
            raise OSError(errno.ENOSPC, "No space left on device")  # e.g. from a writer given out.path()
    assert names(tmp_path) == []


def test_output_error_messages():
    assert str(output_error(OSError(errno.ENOSPC, "x"), "a.rrd")) == \
        "no space left on device writing a.rrd; free some space or write elsewhere"
    assert str(output_error(OSError(errno.EROFS, "x"), "a.rrd")) == \
        "read-only file system: cannot write a.rrd; write to another folder"
    assert output_error(OSError(errno.EBADF, "x"), "a.rrd") is None


def test_a_fifo_is_written_through_and_stays_a_fifo(tmp_path):
    """Renaming a temp onto a FIFO replaced it (its reader waited for good); on a device node (/dev/null
    as root) it replaced the device. Such an output is written through; a regular file is not."""
    import stat

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    with OutputSet([fifo, tmp_path / "m.json"]) as out:
        out.open(fifo, "wb").write(b"frames")
        out.open(tmp_path / "m.json").write("{}")
    reader.join(5)
    assert got == [b"frames"] and stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert (tmp_path / "m.json").read_text() == "{}"
    assert outputs.is_stream("/dev/null") and outputs.is_stream("/dev/stdout") and outputs.is_stream(fifo)
    assert not outputs.is_stream(tmp_path / "m.json") and not outputs.is_stream(tmp_path / "new.json")
    assert [outputs.descriptor_of(p) for p in ("/dev/stdout", "/dev/fd/7", "/proc/self/fd/3", "/dev/null")] == \
        [1, 7, 3, None]
    with pytest.raises(AccumError, match="two outputs are the same file"):   # one descriptor, two names
        OutputSet(["/dev/stdout", "/dev/fd/1"])
    with OutputSet(["/dev/null", "/dev/./null"]):   # discarding two outputs is fine
        pass


def test_a_socket_is_refused(tmp_path):
    import socket

    path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(path))
        with pytest.raises(AccumError, match="is a socket; give a file, a FIFO or /dev/stdout"):
            OutputSet([path])


def test_symlink_stays_a_link_and_mode_is_kept(tmp_path):
    real = tmp_path / "store" / "model.json"
    real.parent.mkdir()
    real.write_text("old")
    real.chmod(0o600)
    link = tmp_path / "model.json"
    link.symlink_to(real)
    with atomic_open(link) as f:
        f.write("new")
    assert link.is_symlink() and os.readlink(link) == str(real)
    assert real.read_text() == "new" and (real.stat().st_mode & 0o777) == 0o600
    assert names(real.parent) == ["model.json"]


def test_new_file_mode_follows_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        with atomic_path(tmp_path / "run.rrd") as temp:
            assert (os.stat(temp).st_mode & 0o777) == 0o600
    finally:
        os.umask(old)
    assert ((tmp_path / "run.rrd").stat().st_mode & 0o777) == 0o640


@pytest.mark.parametrize("other_thread", [False, True])
def test_interrupt_during_the_renames_does_not_split_the_set(tmp_path, monkeypatch, other_thread):
    # With another thread alive the kernel hands it the signal the main thread blocks.
    stop = threading.Event()
    if other_thread:
        threading.Thread(target=stop.wait, daemon=True).start()
    paths = [tmp_path / f"{i}.json" for i in range(3)]
    replace = os.replace
    calls = []

    def replace_then_interrupt(src, dst):
        replace(src, dst)
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # held back until all three are renamed

    monkeypatch.setattr(outputs.os, "replace", replace_then_interrupt)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # other tests' libraries replace it
    try:
        with pytest.raises(KeyboardInterrupt):
            with OutputSet(paths) as out:
                for p in paths:
                    out.open(p).write("new")
            # A signal the kernel handed to the other thread reaches Python when that thread next runs,
            # which on a loaded machine can be after the block: wait for it here (bounded), not in pytest.
            for _ in range(500):
                time.sleep(0.01)
    finally:
        signal.signal(signal.SIGINT, previous)
        stop.set()
    assert len(calls) == 3 and all(p.read_text() == "new" for p in paths)
    assert names(tmp_path) == ["0.json", "1.json", "2.json"]


def test_sigterm_becomes_keyboard_interrupt(tmp_path):
    previous = signal.getsignal(signal.SIGTERM)
    try:
        interrupt_on_sigterm()
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            with OutputSet([tmp_path / "m.json"]) as out:
                out.open(tmp_path / "m.json").write("new")
                os.kill(os.getpid(), signal.SIGTERM)
                for _ in range(500):   # bounded: another thread may take the signal (see above)
                    time.sleep(0.01)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert names(tmp_path) == []


def test_an_interrupt_inside_the_compiler_waits_for_the_next_check(tmp_path):
    """A signal while numba or llvmlite run Python code is noted, not raised there (a ctypes callback
    would drop it or leave LLVM broken); the next check raises it, and an OutputSet about to commit
    abandons its outputs instead."""
    from types import SimpleNamespace

    from accumcli.outputs import _raise_interrupt, raise_pending_interrupt

    def frame(path, caller=None):
        return SimpleNamespace(f_code=SimpleNamespace(co_filename=path), f_back=caller)

    compiling = frame("/venv/lib/python3.11/site-packages/llvmlite/binding/executionengine.py",
                      frame("/work/accumcli/lines2d.py"))
    _raise_interrupt(signal.SIGTERM, compiling)                     # noted, not raised
    target = tmp_path / "m.json"
    target.write_text("previous")
    with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
        with OutputSet([target]) as out:
            out.open(target).write("new")
    assert target.read_text() == "previous" and names(tmp_path) == ["m.json"]
    raise_pending_interrupt()                                        # raised once only
    with pytest.raises(KeyboardInterrupt, match="SIGINT"):
        _raise_interrupt(signal.SIGINT, frame("/work/accumcli/lines2d.py"))   # elsewhere: at once


def test_recording_writer_is_atomic(tmp_path):
    target = tmp_path / "rec.mcap"
    with pytest.raises(RuntimeError):
        with RecordingWriter(target) as w:
            w.metadata("x", {"a": 1})
            raise RuntimeError("stop")
    assert names(tmp_path) == []
    with RecordingWriter(target) as w:
        w.metadata("x", {"a": 1})
    assert target.read_bytes().startswith(b"\x89MCAP")
    with OutputSet([target]) as out:
        with RecordingWriter(out.open(target, "wb")) as w:
            w.metadata("y", {"b": 2})
    assert b"y" in target.read_bytes() and names(tmp_path) == ["rec.mcap"]
