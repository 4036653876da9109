"""The simulation loop: time stepping, rendering and the event integrator's commits (``render``), and the
choice of quality settings a scene needs (``auto``)."""
from .render import RenderSummary, render_events, render_frames  # noqa: F401
