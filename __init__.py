"""Spectral render benchmark: Blender extension entry point.

Only register()/unregister() touch bpy, so the pure-Python parts (exporters/, batch/) import
without Blender.
"""


def register():
    from .addon import register as _register
    _register()


def unregister():
    from .addon import unregister as _unregister
    _unregister()
