"""The bundled models' names: the one list `scgen render --model NAME` takes, light enough for the command
line's help. Their builders are scgen.assets (`make assets`); scgen.scenes.model loads them."""

BUNDLED_MODELS = {  # name: what it is (docs/dataset.md, "The bundled models")
    "spacecraft": "the default: a box bus, two unequal wings, a dish; near-symmetric",
    "cubesat": "a 6U CubeSat with deployed wings of unequal length",
    "smallsat": "a Tango-like small satellite: one top panel and five antennas, no symmetry",
    "geosat": "a GEO communication satellite: two long arrays, two reflectors",
    "upper_stage": "a spent upper stage (debris): a body of revolution, continuous symmetry about z",
}
DEFAULT_MODEL = "spacecraft"
