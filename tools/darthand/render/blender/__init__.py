"""Scripts that run inside Blender's Python (bpy from PyPI, in its own virtual environment: bpy pins numpy < 2, the
project uses numpy 2). They import only bpy, mathutils, numpy and the standard library, and talk to darthand through
JSON lines and npz files (render/cycles.py starts them)."""
