"""darthand: DART-style articulated hand assets in MANO layout.

Stages (one sub-package each): model, template, textures, accessories, export, render, validate.
"""

__version__ = "0.1.0"
