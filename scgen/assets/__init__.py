"""The bundled spacecraft: its builder (`python -m scgen.assets.build_spacecraft`, `make assets`) and the
built model in `spacecraft/`, package data that scgen.scenes.model reads (BUNDLED_MODEL_DIR)."""
