"""All output files of one run, written as a set.

``OutputSet(paths)`` checks every output before any work starts (the folder
exists and takes a new file, tried with a real one; the name is not a folder,
not given twice and not too long), hands out a temporary file per output in the
folder of the file it replaces (short names ``.accum-XXXXXXXX.tmp``, so any name
the file system allows works), and on success renames them all onto their
targets with SIGINT and SIGTERM held back (``signals_blocked``), so an interrupt
cannot split the set; only a rename that fails although the start-up probe
succeeded could. On any exception (KeyboardInterrupt and SystemExit included) it
removes its temporary files and leaves the previous outputs as they were. A full
disk, a read-only file system or a refused permission while writing an output
becomes a one-line AccumError naming it. A symlinked output stays a link (its
target is replaced); an existing output keeps its mode, a new one gets 0o666
minus the umask.

Usage::

    with OutputSet(["out/model.json", "out/run.rrd"]) as out:   # checks here, before the work
        log = RerunLog(..., rrd=out.path("out/run.rrd"))  # a path, for writers that open the file
        ...
        log.close()
        write_model(out.open("out/model.json"), model)     # an open file ("w" UTF-8 text or "wb")
    # here both files are in place, or (after an exception) neither changed

Outputs never handed out (``open``/``path`` not called) are left untouched.

An output that is not a regular file (a device such as ``/dev/null``, a FIFO, ``/dev/stdout``:
``is_stream``) is written into, not replaced: renaming a file onto it replaced the device node
itself (``--rrd /dev/null`` as root turned /dev/null into a file) or the FIFO its reader waited
on. Its temporary file is in the system's temporary folder (writers such as MCAP's need to seek)
and is copied into it at commit, first of the set; a run that fails writes nothing into it.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import signal
import stat
import tempfile
import threading
from pathlib import Path
from typing import Iterable

from .errors import AccumError

TEMP_PREFIX, TEMP_SUFFIX = ".accum-", ".tmp"
BLOCKED = {signal.SIGINT, signal.SIGTERM}
_FAULTS = {errno.ENOSPC: ("no space left on device writing {}", "free some space or write elsewhere"),
           errno.EDQUOT: ("disk quota exceeded writing {}", "free some space or write elsewhere"),
           errno.EROFS: ("read-only file system: cannot write {}", "write to another folder"),
           errno.EACCES: ("permission denied writing {}", "choose a folder you can write to"),
           errno.EPERM: ("operation not permitted writing {}", "choose a folder you can write to"),
           errno.EFBIG: ("file too large writing {}", "write to another file system"),
           errno.EPIPE: ("the reader of {} closed it before the output was written", "keep it open to the end"),
           # a folder that exists but makes no file (/proc)
           errno.ENOENT: ("no file can be made for {}", "choose a folder you can write to"),
           errno.EIO: ("input/output error writing {}", "check the disk or write elsewhere"),
           errno.EMFILE: ("too many open files writing {}", "raise the limit (ulimit -n)"),
           errno.ENFILE: ("too many open files in the system writing {}", "close some programs")}


_NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def output_error(error: OSError, path) -> AccumError | None:
    """The one-line AccumError for an OSError a user can fix (full disk, read-only, permission)
    while writing ``path``; None for any other error (a bug, keep its traceback)."""
    if error.errno not in _FAULTS:
        return None
    what, hint = _FAULTS[error.errno]
    return AccumError(f"{what.format(path)}; {hint}")


def _raise_output_error(error: OSError, path):
    fault = output_error(error, path)
    if fault is None:
        raise error
    raise fault from None


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def signals_blocked():
    """Hold SIGINT and SIGTERM back until the block ends, then deliver them.

    ``pthread_sigmask`` blocks them in the calling thread; in a process with other
    threads (Rerun's, thread pools) the kernel may deliver them to another thread,
    so in the main thread their Python handlers are also replaced by one that notes
    the signal, and the noted signals are raised again once the handlers are back."""
    held = []
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for sig in BLOCKED:
            if signal.getsignal(sig) is not None:  # None: a handler not set from Python, left alone
                previous[sig] = signal.signal(sig, lambda signum, frame: held.append(signum))
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, BLOCKED)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(held):
            signal.raise_signal(sig)


_pending: list[int] = []    # interrupts noted while the compiler ran, raised at the next check
_received: list[int] = []   # every interrupt this process was sent (``interrupt_received``)


def _raise_interrupt(signum, frame):
    """SIGINT's and SIGTERM's handler: KeyboardInterrupt, except while numba or llvmlite run Python
    code (compiling a kernel, or loading one from the cache, on its first call). There it would be
    raised inside a ctypes callback, which drops it ("Exception ignored on calling ctypes callback
    function": the run went on and replaced the outputs, exit 0) or leaves LLVM broken (a
    segmentation fault, exit -11: both seen in a fresh clone's CI, SIGTERM 1.5 s into
    ``accum accumulate``). So it is noted there and raised at the next check
    (``raise_pending_interrupt``: every progress report of the CLI, and before an ``OutputSet``
    commits)."""
    _received.append(signum)
    if _in_compiler(frame):
        _pending.append(signum)
        return
    raise KeyboardInterrupt(signal.Signals(signum).name)


def interrupt_received() -> bool:
    """Whether SIGINT or SIGTERM reached this process: C code that a KeyboardInterrupt interrupts may
    hand on another error in its place (numpy's comparison of structured arrays a TypeError, seen in a
    fresh clone's CI: SIGTERM 1.5 s into accumulate, inside ``np.unique(..., axis=0)``)."""
    return bool(_received)


def _in_compiler(frame) -> bool:
    """Whether ``frame`` or a frame that called it is numba's or llvmlite's Python code."""
    while frame is not None:
        path = frame.f_code.co_filename
        if f"{os.sep}numba{os.sep}" in path or f"{os.sep}llvmlite{os.sep}" in path:
            return True
        frame = frame.f_back
    return False


def raise_pending_interrupt() -> None:
    """Raise the KeyboardInterrupt of a signal that arrived while the compiler ran (if any)."""
    if _pending:
        signum = _pending[0]
        _pending.clear()
        raise KeyboardInterrupt(signal.Signals(signum).name)


def caused_by_interrupt(error: BaseException) -> bool:
    """True if a KeyboardInterrupt is in ``error``'s chain of causes: a signal that arrives while C
    code calls back into Python (numba loading a cached kernel on its first call, for one) raises
    KeyboardInterrupt there, which the C code hands on wrapped in a SystemError."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False


def interrupt_on_sigterm() -> None:
    """Make SIGTERM raise KeyboardInterrupt like SIGINT does, so an OutputSet cleans up on
    both, and neither raise it inside the compiler (``_raise_interrupt``; SIGINT only where it
    has Python's default handler: an ignored one stays ignored). Call once, from the main thread,
    e.g. at CLI start."""
    signal.signal(signal.SIGTERM, _raise_interrupt)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _raise_interrupt)


class _GuardedFile:
    """A file whose write errors a user can fix become AccumError naming the output."""

    def __init__(self, file, name: str):
        self._file, self._name = file, name

    def write(self, data):
        try:
            return self._file.write(data)
        except OSError as e:
            _raise_output_error(e, self._name)

    def writelines(self, lines):
        for line in lines:
            self.write(line)

    def flush(self):
        try:
            self._file.flush()
        except OSError as e:
            _raise_output_error(e, self._name)

    def close(self):
        """A no-op: the OutputSet closes its files when the set is committed or abandoned."""

    @property
    def closed(self) -> bool:
        return self._file.closed

    def __getattr__(self, name):
        return getattr(self._file, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return None


def descriptor_of(path) -> int | None:
    """The file descriptor a path names (/dev/stdout 1, /dev/stderr 2, /dev/fd/N and this process's
    /proc/<pid or self>/fd/N: N), or None; through symlinks to such a name."""
    for name in dict.fromkeys((os.path.abspath(os.fspath(path)), os.path.realpath(path))):
        if name in ("/dev/stdout", "/dev/stderr"):
            return 1 if name == "/dev/stdout" else 2
        parts = name.split("/")
        if (name.startswith("/dev/fd/") and len(parts) == 4) or (
                len(parts) == 5 and parts[1] == "proc" and parts[2] in ("self", str(os.getpid())) and parts[3] == "fd"):
            if parts[-1].isdigit():
                return int(parts[-1])
    return None


def names_open_file(path, fd: int) -> bool:
    """Whether ``path`` is the file open as descriptor ``fd`` (same device and inode; False if either
    cannot be looked at)."""
    try:
        found, open_file = os.stat(path), os.fstat(fd)
    except (OSError, ValueError, TypeError):
        return False
    return (found.st_dev, found.st_ino) == (open_file.st_dev, open_file.st_ino)


def is_stream(path) -> bool:
    """Whether output ``path`` is written into rather than replaced (see the module docstring):
    an existing device or FIFO, or a name of an open file descriptor (``descriptor_of``: replacing
    what it resolves to, a regular file a shell redirected to, loses the output)."""
    if descriptor_of(path) is not None:
        return True
    try:
        mode = os.stat(path).st_mode
    except OSError:   # does not exist (yet): a new regular file
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode) or stat.S_ISBLK(mode) or stat.S_ISSOCK(mode)


class _Output:
    """One output: what the user named, the file that is replaced (a symlink's target), its temp;
    ``stream``: a device, FIFO or stdout, written into at commit (``OutputSet._pour``)."""

    def __init__(self, given: str):
        self.given = given
        self.stream = is_stream(given)
        self.target = Path(os.path.realpath(given)) if os.path.islink(given) and not self.stream else Path(given)
        self.temp: str | None = None
        self.file = None


class OutputSet:
    """Temporary files for all outputs of a run, renamed onto their targets together on success."""

    def __init__(self, paths: Iterable, inputs: Iterable = ()):
        """Check every output now (raises AccumError with one line): a file name, not a folder,
        not given twice, not one of the run's ``inputs`` (which it would replace before they are
        read, or while they are), short enough for its folder, in an existing folder that takes a
        new file. None entries (outputs not asked for, inputs not given) are skipped."""
        self._outputs: dict[str, _Output] = {}
        self._done = False
        for path in paths:
            if path is None or path == "":
                continue   # an output not asked for
            given = os.fspath(path)
            if given in self._outputs:
                raise AccumError(f"{given}: given twice as an output; give each output once")
            self._outputs[given] = _check(_Output(given))
        targets = [_identity(o) for o in self._outputs.values()]
        if len(set(targets)) < len(targets):
            raise AccumError(f"two outputs are the same file ({', '.join(self._outputs)}); give each output once")
        for source in inputs:
            if source is None or source == "" or not os.path.exists(source):
                continue
            for out in self._outputs.values():
                if os.path.exists(out.target) and os.path.samefile(source, out.target):
                    raise AccumError(f"{out.given}: is also an input of this run ({os.fspath(source)}); "
                                     "write the output to another file")

    @property
    def paths(self) -> list[str]:
        """The outputs as given, in order."""
        return list(self._outputs)

    def _output(self, path) -> _Output:
        key = os.fspath(path)
        if self._done:
            raise RuntimeError(f"{key}: the output set is already finished")
        if key not in self._outputs:
            raise KeyError(f"{key} is not an output of this set ({', '.join(self._outputs)})")
        return self._outputs[key]

    def path(self, path) -> str:
        """The temporary path standing for output ``path`` (created empty, mode 0o600, in the
        target's folder, or for a stream in the system's temporary folder); whatever is there at
        commit replaces the target (is copied into the stream)."""
        out = self._output(path)
        if out.temp is None:
            try:
                fd, out.temp = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX,
                                                dir=None if out.stream else out.target.parent)
            except OSError as e:
                _raise_output_error(e, out.given)
            os.close(fd)
        return out.temp

    def open(self, path, mode: str = "w"):
        """The temporary file for output ``path`` opened for writing (``"w"``: UTF-8 text,
        ``"wb"``: binary). Write errors a user can fix (full disk...) raise AccumError naming
        ``path``. Closing it is optional: the set flushes and closes it at the end."""
        if mode not in ("w", "wb"):
            raise ValueError(f"mode {mode!r}: expected 'w' or 'wb'")
        out = self._output(path)
        if out.file is not None:
            raise RuntimeError(f"{out.given} is already open")
        temp = self.path(path)
        try:
            raw = open(temp, mode, encoding="utf-8" if mode == "w" else None)
        except OSError as e:
            _raise_output_error(e, out.given)
        out.file = _GuardedFile(raw, out.given)
        return out.file

    def commit(self) -> None:
        """Flush, fsync and close every file handed out, then rename every temp onto its target
        with SIGINT/SIGTERM held back. Called by ``__exit__`` when the block ends without error; an
        interrupt noted while the compiler ran (``raise_pending_interrupt``) is raised instead."""
        raise_pending_interrupt()
        for out in self._outputs.values():
            if out.stream and out.temp is not None:
                self._pour(out)
        used = [o for o in self._outputs.values() if o.temp is not None]
        mask = _umask()
        for out in used:
            try:
                if out.file is not None and not out.file.closed:
                    out.file.flush()
                    os.fsync(out.file.fileno())
                    out.file._file.close()
                try:
                    mode = stat.S_IMODE(os.stat(out.target).st_mode)
                except FileNotFoundError:
                    mode = 0o666 & ~mask
                os.chmod(out.temp, mode)
            except OSError as e:
                _raise_output_error(e, out.given)
        with signals_blocked():
            for out in used:
                try:
                    os.replace(out.temp, out.target)
                except OSError as e:
                    _raise_output_error(e, out.given)
                out.temp = None
            self._done = True

    def _pour(self, out: _Output) -> None:
        """Copy a stream's temporary file into it (its descriptor duplicated, for /dev/stdout and the
        like: reopened by name a shell's redirect was truncated, its >> lost), and remove the temp."""
        try:
            if out.file is not None and not out.file.closed:
                out.file.flush()
                out.file._file.close()
            fd = descriptor_of(out.given)
            with open(out.temp, "rb") as source, open(os.dup(fd) if fd is not None else out.given, "wb") as sink:
                shutil.copyfileobj(source, sink, 1 << 20)
        except OSError as e:
            _raise_output_error(e, out.given)
        os.unlink(out.temp)
        out.temp = None

    def abandon(self) -> None:
        """Close and remove every temporary file; the targets stay as they were."""
        with signals_blocked():
            for out in self._outputs.values():
                if out.file is not None:
                    with contextlib.suppress(OSError):
                        out.file._file.close()
                if out.temp is not None:
                    with contextlib.suppress(FileNotFoundError):
                        os.unlink(out.temp)
                    out.temp = None
            self._done = True

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self.commit()
            except BaseException:
                self.abandon()
                raise
            return
        temps = {o.given: o.temp for o in self._outputs.values()}
        self.abandon()
        if isinstance(exc, OSError):
            name = next((o.given for o in self._outputs.values() if exc.filename is not None
                         and os.fspath(exc.filename) in (temps[o.given], o.given, str(o.target))), None)
            if name is None and exc.filename is None and exc.errno in _NO_ROOM:
                name = ", ".join(self._outputs)  # a full disk while a writer of ours wrote (no file named)
            fault = output_error(exc, name) if name is not None else None
            if fault is not None:
                raise fault from None


def _identity(out: _Output):
    """What two outputs must not share: a stream's file (device and inode: /dev/stdout and /dev/fd/1
    are one), else the target's absolute path."""
    if out.stream:
        fd = descriptor_of(out.given)
        with contextlib.suppress(OSError):
            found = os.fstat(fd) if fd is not None else os.stat(out.given)
            if fd is None and stat.S_ISCHR(found.st_mode):
                return ("device", id(out))   # /dev/null for two outputs: both discarded, nothing to mix
            return ("file", found.st_dev, found.st_ino)
    return os.path.abspath(out.target)


def _check(out: _Output) -> _Output:
    """``out`` if it can be written; AccumError saying why not (tried with a real temporary file;
    a stream must take writing)."""
    given, target = out.given, out.target
    if out.stream:
        if descriptor_of(given) is None and stat.S_ISSOCK(os.stat(given).st_mode):
            raise AccumError(f"{given}: is a socket; give a file, a FIFO or /dev/stdout")
        if not os.access(given, os.W_OK):
            what = "does not exist" if not os.path.exists(given) else "is not writable"
            raise AccumError(f"{given}: {what}; give a file to write")
        return out
    if given.endswith(os.sep) or os.path.isdir(target):
        raise AccumError(f"{given}: is a folder; give a file name")
    folder = target.parent
    if not os.path.isdir(folder):
        what = "is not a folder" if os.path.exists(folder) else "does not exist"
        raise AccumError(f"{given}: the folder {folder} {what}; create it or write elsewhere")
    try:
        limit = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        limit = 255
    if len(os.fsencode(target.name)) > limit:
        raise AccumError(f"{given}: the file name is {len(os.fsencode(target.name))} bytes, more than the "
                         f"{limit} its folder allows; give a shorter name")
    try:
        fd, probe = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=TEMP_SUFFIX, dir=folder)
    except OSError as e:
        fault = output_error(e, given)
        if fault is None:
            raise
        raise AccumError(f"{given}: cannot create a file in {folder} ({os.strerror(e.errno)}); "
                         "choose a folder you can write to") from None
    os.close(fd)
    os.unlink(probe)
    return out
