"""What the benchmark modules share: the model they measure."""

from __future__ import annotations

from pathlib import Path

BUILT_MODEL = Path("build/model/right.npz")


def bench_model():
    """(model, name): the wrist-enhanced model `make assets` built, else the open template with the wrist added."""
    from darthand.model.load import load_model
    from darthand.model.wrist import add_wrist

    if BUILT_MODEL.is_file():
        return load_model(BUILT_MODEL), str(BUILT_MODEL)
    return add_wrist(load_model("open")), "open + wrist"
