"""scgen: dense-labelled synthetic 6D-pose datasets of one spacecraft."""

__version__ = "0.1.0"
