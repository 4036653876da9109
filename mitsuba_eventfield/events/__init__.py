"""Events: the in-memory stream (``stream.EventStream``), event files (``mitsuba_eventfield.eventio``) and
previews (``preview``)."""
from .stream import EventStream  # noqa: F401
