"""benchmarks/element_costs.py: each variant changes one element of the dataset's render settings and nothing else."""

from benchmarks import element_costs
from benchmarks.render_rays import default_settings


def test_each_variant_changes_its_element_only_and_leaves_the_defaults_alone():
    base = default_settings()
    before = repr(base)
    for name, (_, changes) in element_costs.VARIANTS.items():
        s = element_costs.variant_settings(base, changes)
        differing = {k for k in set(s) | set(base) if s.get(k) != base.get(k)}
        assert differing == ({*changes} if name != "default" else set()), name
        for section, value in changes.items():
            if not isinstance(base.get(section), dict):
                assert s[section] == value                # a setting that was off (the film): set whole
            else:
                assert {k: s[section][k] for k in value} == value
                assert {k: v for k, v in s[section].items() if k not in value} == \
                    {k: v for k, v in base[section].items() if k not in value}
    assert repr(base) == before                     # the defaults are copied, never changed


def test_summary_lists_what_each_element_adds():
    res = {"frames": 2, "rounds": 1, "cpu_ms_per_frame": {"default": 100.0, "dual-skin": 150.0},
           "added_ms": {"default": 0.0, "dual-skin": 50.0}, "what": {"default": "d", "dual-skin": "two lobes"}}
    text = element_costs.summary(res)
    assert text.splitlines()[0].startswith("element costs: default frame 100.0 ms") and "+50.0 ms" in text
