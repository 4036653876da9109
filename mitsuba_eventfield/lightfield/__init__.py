"""Light fields from events: reconstruction of log frames (``reconstruct``), views of spatially multiplexed
films (``views``), the ``LightField`` with its exact view mappings (``model``) and light fields made from event
streams (``streams``)."""
from .model import (Disparity, LightField, from_galvo, from_spatial, galvo_period_starts, galvo_steps_per_period,
                    galvo_view_times)
from .streams import from_events, galvo_lightfields
