"""Relative navigation along a sequence: a filter (MEKF) around the pose network's per-frame poses, its
smoother, and the measurement noise calibrated from the network's confidence. Pure numpy/scipy, knows
nothing of images: predict's tracker and eval's sequence figures both run on it (docs/navigation.md)."""
