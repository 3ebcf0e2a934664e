"""Blender UI of the extension: annotation properties, operators, panels."""
from . import benchmark, operators, panels, preferences, properties

_MODULES = (properties, preferences, benchmark, operators, panels)


def register():
    for m in _MODULES:
        m.register()


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
