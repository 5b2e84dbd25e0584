"""The detector that finds the target's box for the pose network: its model, training and inference."""
