"""Checking the export options both writers take (influences, correctives, texture size)."""

from __future__ import annotations

from darthand.errors import InputError
from darthand.export.correctives import parse_correctives
from darthand.model.layout import NUM_JOINTS


def check_export_options(influences: int | None, correctives: str, texture_size: int | None) -> None:
    """InputError naming the option when the influences (1..16 or None), correctives (`parse_correctives`) or
    texture size (pixels, positive or None) an export was asked for are invalid."""
    if influences is not None and not 1 <= influences <= NUM_JOINTS:
        raise InputError(f"--influences: {influences} is outside 1..{NUM_JOINTS} (or 'all')")
    parse_correctives(correctives)
    if texture_size is not None and texture_size < 1:
        raise InputError(f"--texture-size: must be a positive number of pixels, got {texture_size}")
