"""The bundled scenes, installed as package data ``mitsuba_eventfield.scenes``: find them with
``mitsuba_eventfield.scene.bundled_scene("fan/fan.xml")``. ``build_assets.py`` rebuilds their textures and
meshes."""
