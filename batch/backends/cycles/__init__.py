"""Blender Cycles (an RGB renderer): the backend and its worker process (bpy)."""
