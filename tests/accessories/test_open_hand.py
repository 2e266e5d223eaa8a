"""The catalogue on the real open template (slow): plausible fitted sizes, no penetration at rest."""

from pathlib import Path

import pytest

from darthand.accessories import catalog as cat
from darthand.accessories.build import build_accessories

TEMPLATE = Path(__file__).resolve().parents[2] / "assets_src" / "template" / "open_right.npz"


@pytest.mark.slow
@pytest.mark.skipif(not TEMPLATE.is_file(), reason="open template not imported yet")
def test_fifty_on_the_open_hand(tmp_path):
    from darthand.model.npz_io import load_npz
    from darthand.model.wrist import add_wrist

    hand = add_wrist(load_npz(TEMPLATE))
    catalog = build_accessories(hand, cat.load_spec(), tmp_path, n_sampled=0, gestures=["fist", "flat"],
                                sheet=False)
    acc = catalog["accessories"]
    assert len(acc) == 50
    for a in acc:
        pen = a["max_penetration_mm"]
        size = a["fitted_size"]
        if a["type"] == "ring":
            assert 7.0 < size["inner_radius_mm"] < 13.5                  # adult ring sizes (EU 44..85)
            assert pen["fit_rest"] < 0.05
            assert a["max_axis_drift_mm"] < 1e-6
        elif a["type"] in ("watch", "bracelet"):
            assert 18.0 < size["inner_a_mm"] < 40.0 and 18.0 < size["inner_b_mm"] < 45.0
            assert pen["rest"] < 0.05 and a["max_axis_drift_mm"] < 1e-6
        else:
            assert a["parent_joint"] is None and pen["rest"] < 0.05 and pen["through_rest"] == 0.0
