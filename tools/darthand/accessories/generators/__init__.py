"""Procedural accessory generators: pure functions (params, rng) -> AccessoryMesh in the accessory's local frame.

`params` is one catalogue entry (see assets_src/accessories/catalog.json) with the fitted bore added by `fit`
(`inner_radius` for rings; `inner_a`, `inner_b`, the bore's half-axes along local Y and Z, for wrist items) and
lengths converted to metres. The glove generator also takes the hand model (`glove.glove`).
"""


def rigid_generator(kind: str):
    """The generator function of a rigid accessory type: ring, watch or bracelet."""
    # lazy: item.py is on `darthand --help`'s path, the generators (~45 ms) only where an accessory is built
    from darthand.accessories.generators import bracelet, ring, watch

    return {"ring": ring.ring, "watch": watch.watch, "bracelet": bracelet.bracelet}[kind]
