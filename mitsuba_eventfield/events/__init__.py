"""Events: the in-memory stream (``stream.EventStream``), event files (``io``: read and write every format;
``hdf5``, ``aedat``: their formats; ``disk``: full-disk safety) and previews (``preview``)."""
from .stream import EventStream  # noqa: F401
