"""Blender UI of the extension: annotation properties, operators, panels."""
from . import operators, panels, properties

_MODULES = (properties, operators, panels)


def register():
    for m in _MODULES:
        m.register()


def unregister():
    for m in reversed(_MODULES):
        m.unregister()
