"""`posenet eval`'s and `posenet calibrate`'s defaults, torch-free: the command lines' help reads them
without loading torch."""

BATCH_SIZE = 32  # images per forward pass in eval
CALIBRATION_SPLIT = "val"  # calibrate's split: one the network never trained on, and not the test split
