"""Issue 28's bad inputs in the image paths: each is one line on stderr and exit 2, for `render` and
`render-dataset` alike (a camera whose K cannot be inverted; a background image too large for OpenImageIO)."""

from __future__ import annotations

import json
import struct
import subprocess
import sys
import zlib

import numpy as np
import pytest

from darthand.errors import InputError
from darthand.render.camera import load_camera


def _darthand(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "darthand.cli", *argv], capture_output=True, text=True, timeout=300)


def _png_claiming(path, width: int, height: int) -> None:
    """A PNG whose header claims width x height RGB pixels (its data is a few bytes)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(bytes(3010)))
                     + chunk(b"IEND", b""))


@pytest.mark.parametrize("K", [[[0, 0, 16], [0, 50, 16], [0, 0, 1]], [[1e-300, 0, 16], [0, 50, 16], [0, 0, 1]],
                               [[50, 0, 16], [0, 50, 16], [0, 0, 0]]])
def test_a_singular_K_is_refused_before_any_arithmetic(K):
    """Zero or vanishing focal lengths, or K[2,2] = 0: K has no usable inverse; framing a view on it used to divide
    by zero (numpy's RuntimeWarning printed first)."""
    with np.errstate(all="raise"):          # a warning would now be an exception, not the InputError
        for spec in ({"K": K, "view": "dorsal"}, {"K": K, "R": np.eye(3).tolist(), "t": [0, 0, 0.5]}):
            with pytest.raises(InputError, match="field 'K'"):
                load_camera(spec, np.random.default_rng(0).normal(size=(20, 3)), width=32, height=32)


def test_render_with_a_singular_camera_is_one_line(tmp_path):
    camera = tmp_path / "cam.json"
    camera.write_text(json.dumps({"K": [[0, 0, 16], [0, 50, 16], [0, 0, 1]], "view": "dorsal"}))
    done = _darthand("render", "open", "--camera", str(camera), "--size", "32", "--out", str(tmp_path / "r"))
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Warning" not in done.stderr, done.stderr
    assert done.stderr.startswith("darthand: error: camera: field 'K'"), done.stderr


@pytest.mark.slow
def test_a_background_too_large_to_decode_is_one_line_for_render_and_render_dataset(tmp_path):
    """A PNG header claiming 100000 x 100000 pixels: OpenImageIO refuses it in three lines; both commands print
    the first, on one line, exit 2."""
    (tmp_path / "bg").mkdir()
    huge = tmp_path / "bg" / "huge.png"
    _png_claiming(huge, 100000, 100000)
    runs = {"render": ["render", "open", "--background", str(huge), "--size", "32", "--out", str(tmp_path / "r")],
            "render-dataset": ["render-dataset", "open", "--backgrounds", str(tmp_path / "bg"), "--count", "2",
                               "--size", "32", "--processes", "1", "--out", str(tmp_path / "d")]}
    for name, argv in runs.items():
        done = _darthand(*argv)
        assert done.returncode == 2, (name, done.stderr)
        assert done.stderr.count("\n") == 1, (name, done.stderr)
        assert done.stderr.startswith(f"darthand: error: {huge}: cannot read background image: "), (name,
                                                                                                    done.stderr)


def test_a_background_too_large_to_decode_is_one_line_in_both_readers(tmp_path):
    """The readers behind `render --background` and `render-dataset --backgrounds` (the fast form of the test
    above): one line each, naming the file, with the same words."""
    from darthand.dataset.backgrounds import decode_image
    from darthand.render.image import read_image_buf

    huge = tmp_path / "huge.png"
    _png_claiming(huge, 100000, 100000)
    for read in (lambda: read_image_buf(huge, "background image"), lambda: decode_image(str(huge))):
        with pytest.raises(InputError) as e:
            read()
        assert "\n" not in str(e.value) and str(e.value).startswith(f"{huge}: cannot read background image: ")
