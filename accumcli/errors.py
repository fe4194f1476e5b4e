"""The package's exception tree. The CLI catches ``AccumError`` once and exits 1
with its one-line message; anything else is a bug and keeps its traceback."""


class AccumError(Exception):
    """A problem the user can fix (bad file, missing topic, bad option)."""


class RecordingError(AccumError):
    """A whole recording cannot be used (not an MCAP, truncated, topic missing...)."""


class FileFormatError(AccumError):
    """A model, frames, poses or truth file is not what it claims to be."""


class PoseUnavailable(AccumError):
    """No pose at a given time (outside the transform samples, invalid sample)."""


class InputError(AccumError, ValueError):
    """An array handed to the library is not what it must be (shape, rigidity, finiteness)."""
