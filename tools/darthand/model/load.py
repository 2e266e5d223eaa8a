"""Resolve a MODEL argument to a HandModel: a built-in name, a MANO pickle or a darthand `.npz`."""

from __future__ import annotations

from pathlib import Path

from darthand.errors import InputError
from darthand.model.hand_model import HandModel
from darthand.model.mano_pkl import load_mano_pkl
from darthand.model.mirror import mirror_model
from darthand.model.npz_io import load_npz

REPO_ROOT = Path(__file__).resolve().parents[3]
TEMPLATE_DIR = REPO_ROOT / "assets_src" / "template"
BUILTIN = {"open": "right", "open-right": "right", "open-left": "left"}


def load_model(spec: str | Path) -> HandModel:
    """`open`, `open-right`, `open-left` (the committed CC0 hand), a `.pkl` (MANO) or a `.npz` (darthand)."""
    name = str(spec)
    if name in BUILTIN:
        return open_hand(BUILTIN[name])
    path = Path(name)
    if path.suffix == ".pkl":
        return load_mano_pkl(path)
    if path.suffix == ".npz":
        return load_npz(path)
    if not path.exists():
        raise InputError(f"{name}: no such model file, and not a built-in name ({', '.join(BUILTIN)})")
    raise InputError(f"{name}: unknown model format (expected .pkl or .npz)")


def open_hand(side: str = "right") -> HandModel:
    """The committed open CC0 template (without the wrist), right or mirrored left."""
    path = TEMPLATE_DIR / "open_right.npz"
    if not path.is_file():
        raise InputError(f"{path}: the open hand template is missing from this checkout")
    model = load_npz(path)
    return model if side == "right" else mirror_model(model)
