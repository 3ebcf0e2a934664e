"""Scene IR (plain Python, no bpy), its JSON form, validation, and the renderer writers.

Only ``extract_blender`` imports bpy.
"""
