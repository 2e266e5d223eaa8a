"""Dataset layouts other than the native one, by name: `FORMATS[name](dataset, out, **options)` writes the layout of
a rendered dataset folder (`darthand dataset export DIR --format NAME`, `render-dataset --formats NAME`).

A new layout is one module (dataset/<layout>.py, reading the native layout: labels/, shard records, dataset.json)
and its line in FORMATS; its options, if any, become `DatasetOptions` fields and CLI options of both commands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

from darthand.dataset.coco import write_coco
from darthand.dataset.freihand import write_freihand
from darthand.dataset.hamer import write_hamer
from darthand.dataset.ho3d import write_ho3d
from darthand.dataset.interhand import write_interhand
from darthand.dataset.webdataset import write_webdataset


class Writer(Protocol):
    """Writes a rendered dataset (a folder, dataset/run.py's layout) in another layout into `out` (None: a folder
    named after the layout inside the dataset); returns where. Options every writer accepts: left ('mirror' or
    'skip': what a right-handed layout does with left hands) and allow_non_mano (write MANO parameters of a hand
    that is not MANO's); a writer ignores those that do not apply to it."""

    def __call__(self, dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path: ...


def _freihand(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_freihand(dataset, out, left=left, allow_non_mano=allow_non_mano)


def _webdataset(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_webdataset(dataset, out)


def _hamer(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_hamer(dataset, out, left=left, allow_non_mano=allow_non_mano)


def _coco(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_coco(dataset, out)


def _interhand(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_interhand(dataset, out)


def _ho3d(dataset, out, *, left: str = "mirror", allow_non_mano: bool = False) -> Path:
    return write_ho3d(dataset, out, left=left)


FORMATS: dict[str, Writer] = {"freihand": _freihand, "webdataset": _webdataset, "hamer": _hamer, "coco": _coco,
                              "interhand": _interhand, "ho3d": _ho3d}
