"""The catalogue spec and its expansion: schema, 325 stable ids, counts, seeds independent of other entries."""

import collections
import copy
import json
import re

import jsonschema
import pytest
from darthand.errors import InputError
from darthand.schemas import load_schema
from darthand.textures.catalog import (BASE_CATEGORIES, MAX_TONE_SRGB, OVERLAY_CATEGORIES, default_spec_path,
                                       entry_seed, expand_catalog, load_spec, select, validate_spec)
from texture_hand import entries, spec


def test_shipped_spec_validates_against_its_schema():
    schema = load_schema("texture_catalog_spec.schema.json")
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(json.loads(default_spec_path().read_text()), schema)


def test_dart_counts_325():
    es = entries()
    assert len(es) == 325
    counts = collections.Counter((e.tone, e.category) for e in es if e.kind == "overlay")
    per_tone = {"bandage": 5, "palm_prints": 10, "scars": 20, "tattoos": 20, "moles": 20, "nail_colors": 20}
    for tone in ("dark", "brown", "light"):
        for cat, n in per_tone.items():
            assert counts[(tone, cat)] == n, (tone, cat)
    assert sum(1 for e in es if e.kind == "overlay") == 285
    base = [e for e in es if e.kind == "base_variation"]
    assert len(base) == 40 and {e.category for e in base} <= set(BASE_CATEGORIES)
    assert {e.category for e in es} == set(OVERLAY_CATEGORIES) | set(BASE_CATEGORIES)


def test_ids_are_unique_and_follow_the_pattern():
    ids = [e.id for e in entries()]
    assert len(set(ids)) == len(ids)
    assert "light_tattoos_07" in ids and "base_freckles_03" in ids
    for e in entries():
        assert re.fullmatch(rf"({e.tone}|base)_{e.category}_\d\d", e.id), e.id


def test_entries_are_plain_json_with_ranges_respected():
    s = spec()
    lo, hi = s["offset"]
    for e in entries():
        json.dumps(e.to_json())
        assert lo <= e.offset <= hi
        assert max(e.tone_srgb) + e.offset <= max(MAX_TONE_SRGB, max(e.tone_srgb)) + 1e-5, e.id  # offset: 5 decimals
        assert 1.0 <= e.mst <= 10.0
        if e.kind == "overlay":
            assert abs(e.mst - s["tones"][e.tone]) <= s["tone_jitter"] + 1e-9
        for name, (a, b) in s["skin"].items():
            assert a <= e.params["skin"][name] <= b, name


def test_expansion_is_deterministic_and_independent_of_other_entries():
    again = expand_catalog(load_spec())
    assert [e.to_json() for e in again] == [e.to_json() for e in entries()]
    # Drop a category and change another's count: every remaining entry is unchanged.
    s = copy.deepcopy(spec())
    del s["overlays"]["scars"]
    s["overlays"]["moles"]["count"] = 3
    fewer = {e.id: e.to_json() for e in expand_catalog(s)}
    full = {e.id: e.to_json() for e in entries()}
    assert not any(i.endswith(("scars_00", "moles_05")) for i in fewer)
    for i, e in fewer.items():
        assert e == full[i], i
    # A different catalogue seed changes every entry's seed.
    s2 = copy.deepcopy(spec())
    s2["seed"] += 1
    assert all(a.seed != b.seed for a, b in zip(expand_catalog(s2), entries()))


def test_entry_seed_depends_on_seed_and_id_only():
    assert entry_seed(1, "light_moles_00") == entry_seed(1, "light_moles_00")
    assert entry_seed(1, "light_moles_00") != entry_seed(1, "light_moles_01")
    assert entry_seed(1, "light_moles_00") != entry_seed(2, "light_moles_00")
    assert 0 <= entry_seed(7, "x") < 2 ** 63


def test_nail_colours_cycle_through_the_palette_on_every_tone():
    polishes = [p["name"] for p in spec()["overlays"]["nail_colors"]["polishes"]]
    for tone in ("dark", "brown", "light"):
        got = [e.params["nail_colors"]["polish"] for e in entries() if e.tone == tone and e.category == "nail_colors"]
        assert sorted(got) == sorted(polishes)


def test_select_by_ids_and_categories():
    es = list(entries())
    sub = select(es, ids=["light_tattoos_07"], categories=["bandage"])
    assert [e.id for e in sub] == [e.id for e in es if e.id == "light_tattoos_07" or e.category == "bandage"]
    assert select(es) == es
    with pytest.raises(InputError, match="light_tattoos_99"):
        select(es, ids=["light_tattoos_99"])
    with pytest.raises(InputError, match="tatoos"):
        select(es, categories=["tatoos"])


def test_bad_specs_name_the_field(tmp_path):
    bad = copy.deepcopy(spec())
    bad["overlays"]["tattoos"]["size_mm"] = [10]
    with pytest.raises(InputError, match="overlays.tattoos.size_mm"):
        validate_spec(bad, "spec.json")
    bad = copy.deepcopy(spec())
    bad["offset"] = [0.1, -0.1]
    with pytest.raises(InputError, match="offset"):
        validate_spec(bad, "spec.json")
    bad = copy.deepcopy(spec())
    bad["default"] = "light_moles_99"
    with pytest.raises(InputError, match="'default' 'light_moles_99'"):
        validate_spec(bad, "spec.json")
    p = tmp_path / "broken.json"
    p.write_text("{ not json")
    with pytest.raises(InputError, match="broken.json"):
        load_spec(p)
    with pytest.raises(InputError, match="no such"):
        load_spec(tmp_path / "missing.json")
