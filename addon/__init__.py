"""Blender UI of the extension: annotation properties, operators, panels."""
from ..exporters import blender_properties as properties
from . import benchmark, operators, panels, preferences

_MODULES = (properties, preferences, benchmark, operators, panels)


def register():
    for m in _MODULES:
        m.register()


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
