"""The one exception type for mistakes in what the user gave (files, columns, options).

``InputError`` is a ``ValueError`` so library callers can catch either; the command line turns
it (and any library ``ValueError``) into a one-line message on stderr and exit code 2.
"""

from __future__ import annotations

__all__ = ["InputError"]


class InputError(ValueError):
    """A problem with the user's input; the message names the problem and the fix."""
