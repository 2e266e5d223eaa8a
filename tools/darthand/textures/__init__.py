"""Textures stage: the DART-style catalogue of procedural skin albedo variants for a MANO-layout hand.

Data flow: model (with UVs, or an xatlas atlas: `atlas`) -> baked surface maps per texel (`bake`, rasterised by
`raster`; anatomy fields from `anatomy` / model `regions`, solid noise from `noise`) -> one variant per catalogue entry
(`catalog` expands assets_src/textures/catalog.json; `skin` paints the base and base variations, `overlays` the
overlay categories, on a `canvas`, placed through `surface`) -> files (`imageio`), catalog.json and the contact
sheet (`build`, `sheet`). `commands` holds the CLI command functions.

Main entry points: `build.build_textures(model, spec, out_dir, res, ids, categories, workers)`,
`catalog.load_spec(path)`, `catalog.expand_catalog(spec)`, `variant.render_variant(bake, entry)`,
`bake.bake(model, res)`, `model.atlas.ensure_uvs(model, res)`, `model.regions.derive_face_labels(model)`.
"""
