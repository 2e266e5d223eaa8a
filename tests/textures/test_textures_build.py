"""Building catalogue subsets into a folder: files, catalog.json against its schema, .tx mip levels,
determinism across subsets and worker counts, incremental rebuilds, the contact sheet, the CLI commands."""

import argparse
import json

import jsonschema
import numpy as np
import OpenImageIO as oiio
import pytest
from darthand.errors import InputError
from darthand.fileio import sha256_file
from darthand.schemas import load_schema
from darthand.textures import commands
from darthand.textures.build import build_textures
from darthand.textures.imageio import mip_levels, read_image
from texture_hand import fixture_model, spec

RES = 64
SCHEMA = load_schema("texture_catalog.schema.json")


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("textures")
    catalog = build_textures(fixture_model(), spec(), out, res=RES, ids=["light_tattoos_07", "brown_nail_colors_03"],
                             categories=["bandage"], workers=1, progress=False)
    return out, catalog


def test_catalog_matches_schema_and_files(built):
    out, catalog = built
    jsonschema.validate(catalog, SCHEMA)
    assert json.loads((out / "catalog.json").read_text()) == catalog
    ids = [e["id"] for e in catalog["entries"]]
    assert ids[:5] == [f"dark_bandage_0{i}" for i in range(5)] and "light_tattoos_07" in ids and len(ids) == 17
    for e in catalog["entries"]:
        assert e["resolution"] == RES
        for kind, f in e["files"].items():
            assert f and (out / f).is_file(), (e["id"], kind)
        assert sha256_file(out / e["files"]["albedo"]) == e["sha256"]
        spec_img = oiio.ImageInput.open(str(out / e["files"]["albedo"]))
        s = spec_img.spec()
        assert (s.width, s.height, s.nchannels, s.format) == (RES, RES, 3, oiio.TypeDesc("uint8"))
        assert s.get_string_attribute("oiio:ColorSpace").lower().startswith("srgb")
        spec_img.close()
    for f in (catalog["bake"]["labels"], catalog["bake"]["coverage"], catalog["contact_sheet"]):
        assert (out / f).is_file()


def test_subset_builds_only_the_subset(built):
    out, catalog = built
    pngs = {p.stem for p in out.glob("*.png") if not p.stem.startswith(("roughness_", "labels_", "coverage_",
                                                                          "contact_sheet"))}
    assert pngs == {e["id"] for e in catalog["entries"]}


def test_tx_is_tiled_and_mip_mapped(built):
    out, catalog = built
    e = catalog["entries"][0]
    levels = mip_levels(out / e["files"]["tx"])
    assert levels == [(RES >> k, RES >> k) for k in range(len(levels))] and len(levels) == RES.bit_length()
    inp = oiio.ImageInput.open(str(out / e["files"]["tx"]))
    assert inp.spec().tile_width > 0 and inp.spec().get_string_attribute("wrapmodes") == "clamp,clamp"
    inp.close()
    assert np.array_equal(read_image(out / e["files"]["tx"]), read_image(out / e["files"]["albedo"]))


def test_roughness_maps_for_nail_colours(built):
    out, catalog = built
    e = next(x for x in catalog["entries"] if x["category"] == "nail_colors")
    rough = read_image(out / e["files"]["roughness"])[..., 0].astype(float) / 255
    labels = read_image(out / catalog["bake"]["labels"])[..., 0]
    glossy = (rough < 0.2) & (labels != 255)
    assert glossy.any() and (labels[glossy] == 0).all()  # polish gloss only on nail texels
    assert np.median(rough[labels == 2]) > 0.35


def test_same_entry_byte_identical_across_subsets_order_and_workers(built, tmp_path):
    out, catalog = built
    first = {e["id"]: e["sha256"] for e in catalog["entries"]}
    other = build_textures(fixture_model(), spec(), tmp_path, res=RES,
                           ids=["brown_nail_colors_03", "dark_bandage_02", "light_tattoos_07"], workers=2,
                           progress=False, tx=False, sheet=False)
    for e in other["entries"]:
        assert e["sha256"] == first[e["id"]], e["id"]
        assert e["files"]["tx"] is None


def test_rebuild_skips_up_to_date_entries_and_force_rebuilds(built, tmp_path):
    c1 = build_textures(fixture_model(), spec(), tmp_path, res=RES, ids=["light_moles_00"], workers=1,
                        progress=False, sheet=False)
    png = tmp_path / "light_moles_00.png"
    stamp = png.stat().st_mtime_ns
    c2 = build_textures(fixture_model(), spec(), tmp_path, res=RES, ids=["light_moles_01"], workers=1,
                        progress=False, sheet=False)
    assert png.stat().st_mtime_ns == stamp
    assert [e["id"] for e in c2["entries"]] == ["light_moles_00", "light_moles_01"]
    assert c2["entries"][0] == c1["entries"][0]
    build_textures(fixture_model(), spec(), tmp_path, res=RES, ids=["light_moles_00"], workers=1, progress=False,
                   sheet=False, force=True)
    assert png.stat().st_mtime_ns != stamp
    # A damaged file is rebuilt.
    png.write_bytes(b"broken")
    c3 = build_textures(fixture_model(), spec(), tmp_path, res=RES, ids=["light_moles_00"], workers=1,
                        progress=False, sheet=False)
    assert sha256_file(png) == c1["entries"][0]["sha256"] == c3["entries"][0]["sha256"]


def test_model_without_uvs_gets_an_atlas(tmp_path):
    c = build_textures(fixture_model(with_uvs=False, with_labels=False), spec(), tmp_path, res=RES,
                       ids=["light_nail_colors_00"], workers=1, progress=False, tx=False)
    assert c["bake"]["uvs"] == "xatlas" and (tmp_path / "model_uv.npz").is_file()
    from darthand.model.npz_io import load_npz

    assert load_npz(tmp_path / "model_uv.npz").has_uvs
    jsonschema.validate(c, SCHEMA)


def test_contact_sheet_groups_every_entry_by_category(built):
    """One section per category (a header strip, then rows of tiles), in catalogue order; every tile a hand."""
    from darthand.textures import sheet as sheet_mod

    out, catalog = built
    img = read_image(out / catalog["contact_sheet"])
    groups = {}
    for e in catalog["entries"]:
        groups.setdefault(sheet_mod.group_name(e), []).append(e)
    cols = min(sheet_mod.COLUMNS, max(len(g) for g in groups.values()))
    tile, cell = sheet_mod.TILE, sheet_mod.TILE + sheet_mod.LABEL_HEIGHT
    assert img.shape[1] == tile * cols
    assert img.shape[0] == sum(sheet_mod.HEADER_HEIGHT + -(-len(g) // cols) * cell for g in groups.values())
    y = 0
    for members in groups.values():
        assert (img[y + 2, -2] == sheet_mod.HEADER).all()          # the header strip (its right end has no text)
        y += sheet_mod.HEADER_HEIGHT
        for i in range(len(members)):
            r, c = divmod(i, cols)
            t = img[y + r * cell:y + r * cell + tile, c * tile:(c + 1) * tile].reshape(-1, 3).astype(int)
            assert (np.abs(t - sheet_mod.BACKGROUND).sum(1) > 30).mean() > 0.15
        y += -(-len(members) // cols) * cell
    labels = [sheet_mod.describe(e) for e in catalog["entries"]]
    assert "light 07 ring line" in labels and any(lab.startswith("dark 02 ") for lab in labels)


def _args(**kw):
    base = dict(model=None, out=None, res=None, ids=[], category=[], jobs=1, no_tx=False, no_roughness=False,
                no_sheet=True, force=False, spec=None, json=False)
    base.update(kw)
    return argparse.Namespace(**base)


def test_commands(tmp_path, capsys):
    from darthand.model.npz_io import save_npz

    model_path = tmp_path / "hand.npz"
    save_npz(fixture_model(), model_path)
    out = tmp_path / "tex"
    assert commands.build(_args(model=str(model_path), out=str(out), res=32, ids=["light_scars_00"])) == 0
    assert "1 variants at 32x32" in capsys.readouterr().out
    assert commands.sheet(_args(out=str(out))) == 0
    assert (out / "contact_sheet.png").is_file()
    assert commands.list_entries(_args(category=["moles"])) == 0
    assert "moles (60)" in capsys.readouterr().out
    with pytest.raises(InputError, match="power of two"):
        commands.build(_args(model=str(model_path), out=str(out), res=100))
    with pytest.raises(InputError, match="catalog"):
        commands.sheet(_args(out=str(tmp_path / "nothing")))
    with pytest.raises(InputError, match="not in the catalogue"):
        commands.build(_args(model=str(model_path), out=str(out), res=32, ids=["light_scars_77"]))
