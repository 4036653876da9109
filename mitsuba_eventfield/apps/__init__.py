"""The main job (``demo``: refocus and depth from a galvo event field) and the paper's applications, each built
on the generic pipeline and returning one result type (``result.AppResult``): HDR light fields (``hdr``),
slow-motion refocus (``slomorf``), high-speed refocus and focus tracking with the galvo (``highspeed``), depth
at the scan rate (``scanrate``)."""
