"""User-facing errors.  The CLI prints ``servo: error: <message>`` (one line) and exits
non-zero for any of these; anything else is a bug and says so."""


def first_line(exc: BaseException | str, limit: int = 240) -> str:
    """A foreign library's message made fit for one error line: its first line, at most
    ``limit`` characters (a corrupt file's reader may quote kilobytes of raw bytes)."""
    text = str(exc).strip()
    line = text.splitlines()[0] if text else type(exc).__name__
    return line if len(line) <= limit else line[: limit - 3] + "..."


class ServoError(Exception):
    """Base class: a problem with the user's input or environment, in one line."""

    exit_code = 2


class ConfigError(ServoError):
    """A config file or option is wrong: unknown key, wrong type, out of range."""


class RecordingError(ServoError):
    """A recording is malformed: missing column, NaN, non-monotonic time, too short..."""


class DriverError(ServoError):
    """The drive or the link failed: port gone, peer silent, protocol or lifecycle error."""

    exit_code = 3


class UnstableLoop(ServoError):
    """The closed loop is unstable: a design whose closed loop has poles outside the unit
    circle, or a run that diverged, limit-cycled, sat at a limit or left its stroke (the
    actuator was put in its safe state, what was recorded is kept)."""

    exit_code = 3


class LifecycleError(DriverError):
    """A driver method was called in a state that does not allow it."""


class Interrupted(ServoError):
    """Ctrl-C or SIGTERM stopped a command; the message says what was kept."""

    exit_code = 130
