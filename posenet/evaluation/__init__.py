"""Scoring a pose network on a split: the run (`evaluate`), the field's metrics, per-sequence error and
jitter, and the pictures (`posenet viz`)."""
