"""The sky behind the target, for both backends: backgrounds, Hipparcos stars, Blue Marble, the Moon."""
