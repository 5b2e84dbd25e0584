"""Blender/Cycles: the default backend (bpy). `backend` is the renderer; the rest are its parts."""
