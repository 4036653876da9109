"""Light fields from events: reconstruction of log frames (``reconstruct``), views of spatially multiplexed
films (``views``) and the ``LightField`` with its exact view mappings (``model``)."""
from .model import (Disparity, LightField, from_events, from_galvo, from_spatial, galvo_lightfields,
                    galvo_period_starts, galvo_steps_per_period, galvo_view_times)
