"""The bundled models: their builders from primitives (`python -m scgen.assets.build`, `make assets`) and
the built models in `<name>/` (parts.glb, the BOP PLY, models_info.json), package data that
scgen.scenes.model reads. Their names: scgen.scenes.bundled_models."""
