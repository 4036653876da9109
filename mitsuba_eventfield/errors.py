"""The one exception type users see for bad input; the CLI prints it as a single line."""


class EventFieldError(Exception):
    """Invalid input or unmet precondition, with a message that names the file/field and the allowed range."""


class ConfigError(EventFieldError, ValueError):
    """A value in a file or argument is outside what is allowed."""
