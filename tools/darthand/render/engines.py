"""The engines an image can come from, and their defaults (light: the command line reads them for its help).

    darthand   the fast renderer (render/api.py): Embree and numba, about 0.1 s of CPU a frame
    cycles     Blender's Cycles path tracer (render/cycles.py) through .venv-blender's bpy, with OpenImageDenoise: the
               quality reference, tens of seconds of CPU a frame; labels, masks and maps stay the fast renderer's
"""

ENGINES = ("darthand", "cycles")
DEFAULT_ENGINE = "darthand"
DEFAULT_CYCLES_SAMPLES = 16       # Cycles' samples per pixel, denoised (issue 28 measured its realism at 16)
MAX_CYCLES_SAMPLES = 65536
