"""The paper's applications, each built on the generic pipeline: HDR light fields (``hdr``), slow-motion
refocus (``slomorf``), high-speed refocus and focus tracking with the galvo (``highspeed``), depth at the
scan rate (``mitsuba_eventfield.scanrate``)."""
