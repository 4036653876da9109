"""The one exception type users see for bad input; the CLI prints it as a single line."""
from __future__ import annotations


class EventFieldError(Exception):
    """Invalid input or unmet precondition, with a message that names the file/field and the allowed range."""


class ConfigError(EventFieldError, ValueError):
    """A value in a file or argument is outside what is allowed."""


def plugin_message(e: Exception) -> str | None:
    """The message of the Python exception a plugin raised inside a Mitsuba load (the last ``...Error: ...`` line
    of the traceback Mitsuba embeds in its own error), or None when the error came from Mitsuba itself."""
    import re
    if "Traceback (most recent call last)" not in str(e):
        return None
    errors = re.findall(r"^\s*(?:\w+\.)*\w*(?:Error|Exception): (.+)$", str(e), flags=re.M)
    return errors[-1] if errors else None
