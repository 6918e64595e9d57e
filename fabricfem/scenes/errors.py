"""The error of a scene that cannot be run, and the close-match hint of its messages."""
from __future__ import annotations

import difflib


class SceneError(ValueError):
    """A scene file that cannot be run; the message names the offending key."""


def suggest(name: str, options) -> str:
    """" (did you mean 'x'?)" for the closest of `options` to `name`, or ""."""
    close = difflib.get_close_matches(name, list(options), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""
