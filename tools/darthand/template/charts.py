"""Small charts for the shape-space report, drawn with OpenImageIO (the project has no plotting library).

A chart is a list of panels on one white canvas; a panel maps data coordinates to a pixel rectangle and draws
histograms, curves, bars, ticks and labels into it. Written here because two histograms and a bar chart do not
justify a new dependency; `model.preview.write_png` saves the result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import OpenImageIO as oiio

INK = (0.0, 0.0, 0.0)
GRID = (0.85, 0.85, 0.85)
COLORS = {"samples": (0.55, 0.62, 0.75), "female": (0.80, 0.10, 0.10), "male": (0.05, 0.25, 0.75),
          "pooled": (0.05, 0.05, 0.05), "bar": (0.30, 0.45, 0.70)}
TEXT = 15


def canvas(width: int, height: int) -> oiio.ImageBuf:
    """A white linear-RGB float canvas."""
    buf = oiio.ImageBuf(oiio.ImageSpec(width, height, 3, oiio.FLOAT))
    oiio.ImageBufAlgo.fill(buf, (1.0, 1.0, 1.0))
    return buf


def pixels(buf: oiio.ImageBuf) -> np.ndarray:
    """(H, W, 3) float32 image of a canvas."""
    return buf.get_pixels(oiio.FLOAT).reshape(buf.spec().height, buf.spec().width, 3)


@dataclass
class Panel:
    """Data window (x0, x1) x (y0, y1) drawn into the pixel box (left, top, right, bottom) of `buf`."""

    buf: oiio.ImageBuf
    box: tuple[int, int, int, int]
    x_range: tuple[float, float]
    y_range: tuple[float, float]

    def px(self, x) -> np.ndarray:
        left, _, right, _ = self.box
        return left + (np.asarray(x, dtype=np.float64) - self.x_range[0]) / np.ptp(self.x_range) * (right - left)

    def py(self, y) -> np.ndarray:
        _, top, _, bottom = self.box
        return bottom - (np.asarray(y, dtype=np.float64) - self.y_range[0]) / np.ptp(self.y_range) * (bottom - top)

    def frame(self, title: str, xlabel: str, ylabel: str, xticks, yticks, fmt: str = "{:g}") -> None:
        """Axes box, grid lines at the ticks, tick labels, title and axis labels."""
        left, top, right, bottom = self.box
        for x in xticks:
            px = int(round(float(self.px(x))))
            oiio.ImageBufAlgo.render_line(self.buf, px, top, px, bottom, GRID)
            oiio.ImageBufAlgo.render_text(self.buf, px - 12, bottom + TEXT + 4, fmt.format(x), TEXT, "", INK)
        for y in yticks:
            py = int(round(float(self.py(y))))
            oiio.ImageBufAlgo.render_line(self.buf, left, py, right, py, GRID)
            oiio.ImageBufAlgo.render_text(self.buf, left - 44, py + 5, fmt.format(y), TEXT, "", INK)
        oiio.ImageBufAlgo.render_box(self.buf, left, top, right, bottom, INK)
        oiio.ImageBufAlgo.render_text(self.buf, left, top - 10, title, TEXT + 2, "", INK)
        oiio.ImageBufAlgo.render_text(self.buf, (left + right) // 2 - 4 * len(xlabel), bottom + 2 * TEXT + 10,
                                      xlabel, TEXT, "", INK)
        if ylabel:
            oiio.ImageBufAlgo.render_text(self.buf, left - 44, top - 10 - TEXT - 6, ylabel, TEXT, "", INK)

    def bars(self, edges: np.ndarray, heights: np.ndarray, color, gap: int = 1) -> None:
        """Filled bars between consecutive `edges` (K+1,) with `heights` (K,)."""
        base = int(round(float(self.py(self.y_range[0]))))
        for a, b, h in zip(edges[:-1], edges[1:], heights):
            x0, x1 = int(round(float(self.px(a)))) + gap, int(round(float(self.px(b)))) - gap
            y = int(round(float(self.py(min(h, self.y_range[1])))))
            if x1 > x0 and y < base:
                oiio.ImageBufAlgo.fill(self.buf, color, oiio.ROI(x0, x1, y, base, 0, 1, 0, 3))

    def curve(self, x: np.ndarray, y: np.ndarray, color, width: int = 2) -> None:
        """A polyline through (x, y), `width` pixels thick (drawn as vertically offset copies)."""
        px, py = self.px(x), self.py(np.minimum(y, self.y_range[1]))
        for k in range(width):
            for a in range(len(px) - 1):
                oiio.ImageBufAlgo.render_line(self.buf, int(round(px[a])), int(round(py[a])) + k,
                                              int(round(px[a + 1])), int(round(py[a + 1])) + k, color)

    def legend(self, entries: list[tuple[str, tuple]], corner: str = "right") -> None:
        """Coloured swatches with labels in the panel's top corner."""
        left, top, right, _ = self.box
        x = right - 230 if corner == "right" else left + 10
        for k, (label, color) in enumerate(entries):
            y = top + 10 + k * (TEXT + 6)
            oiio.ImageBufAlgo.fill(self.buf, color, oiio.ROI(x, x + 16, y, y + 10, 0, 1, 0, 3))
            oiio.ImageBufAlgo.render_text(self.buf, x + 22, y + 10, label, TEXT, "", INK)


def normal_pdf(x: np.ndarray, mean: float, sd: float) -> np.ndarray:
    return np.exp(-0.5 * ((x - mean) / sd) ** 2) / (sd * np.sqrt(2 * np.pi))


def ticks(lo: float, hi: float, step: float) -> np.ndarray:
    """Multiples of `step` within [lo, hi]."""
    return np.arange(np.ceil(lo / step) * step, hi + 1e-9, step)
