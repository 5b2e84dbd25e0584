"""What is sampled, and how the camera is set: the built-in defaults, a TOML/YAML file's overrides, and
their checks, each a one-line error naming the key and the bad value. Nothing here draws a sample."""
