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
    """An argument of the wrong shape or value given to the library (or an option given to the CLI)."""


def one_line(e: Exception, limit: int = 300) -> str:
    """An exception's message on one line, at most ``limit`` characters (for a one-line error or warning)."""
    return " ".join(str(e).split())[:limit]


def is_whole_number(value) -> bool:
    """An integer (Python's or numpy's), not a bool: what counts, frames and nanoseconds must be."""
    import numbers

    return isinstance(value, numbers.Integral) and not isinstance(value, bool)
