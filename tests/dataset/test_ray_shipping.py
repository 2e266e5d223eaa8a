"""dataset/ray/shipping.catalogue_files (no cluster: the file lists a node is shipped): a catalogue folder or file
gives its catalog.json, absolute, and the files each entry of its list names, all in one group; against the files
the test wrote."""

from __future__ import annotations

import json
from pathlib import Path

from darthand.dataset.ray.shipping import catalogue_files


def _catalogue(root: Path, kind: str, entries: list) -> Path:
    root.mkdir(parents=True)
    (root / "catalog.json").write_text(json.dumps({kind: [{"id": str(i), "files": e} for i, e in enumerate(entries)]}))
    return root


def test_an_object_catalogues_meshes_and_textures_in_one_group(tmp_path):
    root = _catalogue(tmp_path / "objects", "objects", [{"npz": "a.npz", "base_color": "a.png"}, {"npz": "b.npz"}])
    cat, files = catalogue_files(root, "objects", ("npz", "base_color"))
    assert cat == str(root / "catalog.json")     # pytest's folders are absolute
    group = f"catalog:{cat}"
    assert files == [(Path(cat), group), (root / "a.npz", group), (root / "a.png", group),
                     (root / "b.npz", group)]
    assert catalogue_files(root / "catalog.json", "objects", ("npz", "base_color")) == (cat, files)


def test_names_asked_only_and_none_without_names(tmp_path):
    root = _catalogue(tmp_path / "accessories", "accessories", [{"npz": "ring.npz", "base_color_png": "ring.png"}])
    cat, files = catalogue_files(root, "accessories", ("npz",))
    assert [p.name for p, _ in files] == ["catalog.json", "ring.npz"]
    assert catalogue_files(root, "textures") == (cat, [(Path(cat), f"catalog:{cat}")])


def test_no_catalogue_there_and_a_broken_one(tmp_path):
    assert catalogue_files(None, "objects", ("npz",)) == (None, [])
    assert catalogue_files(tmp_path / "none", "objects", ("npz",)) == (str(tmp_path / "none"), [])
    (tmp_path / "broken").mkdir()
    (tmp_path / "broken" / "catalog.json").write_text("{not json")
    cat, files = catalogue_files(tmp_path / "broken", "objects", ("npz",))
    assert files == [(Path(cat), f"catalog:{cat}")]              # the loader reports it
