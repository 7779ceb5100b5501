"""The one exception type for mistakes in what the user gave (files, columns, options), and the
warning that a log's rests move.

``InputError`` is a ``ValueError`` so library callers can catch either; the command line turns
it (and any library ``ValueError``) into a one-line message on stderr and exit code 2. Code that
must tell one mistake from another reads :attr:`InputError.code`, never the message's text.
"""

from __future__ import annotations

__all__ = [
    "GYRO_UNIT",
    "MOVING_RESTS",
    "NOT_A_SENSOR",
    "NO_STILL",
    "SHORT_LOG",
    "WRONG_RATE",
    "InputError",
    "MovingRestsWarning",
]

#: :attr:`InputError.code` of still detection that found no rest.
NO_STILL = "no_still"
#: :attr:`InputError.code` of still detection whose rests move (``poses="auto"`` then goes on to
#: the continuous motion).
MOVING_RESTS = "moving_rests"
#: :attr:`InputError.code` of a log shorter than one still-detection window (a log of shots, one
#: row per pose: the pipeline then asks for its pose column).
SHORT_LOG = "short_log"
#: :attr:`InputError.code` of a gyroscope whose integrated turn contradicts the field sensors'
#: by its unit (deg/s for rad/s), and of a ``--rate`` that contradicts the log.
GYRO_UNIT = "gyro_unit"
WRONG_RATE = "wrong_rate"
#: :attr:`InputError.code` of a per-sensor option that names something other than a sensor.
NOT_A_SENSOR = "not_a_sensor"


class InputError(ValueError):
    """A problem with the user's input; the message names the problem and the fix.

    Parameters
    ----------
    message : str
        One line: the problem and the fix.
    code : str, optional
        A stable identifier for the kind of problem (``NO_STILL``, ...), for the code that
        decides what to do next; ``None`` for the many that need no such decision.
    subject : str, optional
        What the problem is about, when the caller rewords the message (the key of a
        per-sensor option, ...).
    """

    def __init__(self, message: str, *, code: str | None = None, subject: str | None = None):
        super().__init__(message)
        self.code = code
        self.subject = subject


class MovingRestsWarning(UserWarning):
    """Still detection found intervals whose mean turns: the log seems to move without rests
    (``poses="auto"`` then calibrates from the continuous motion when it can)."""
