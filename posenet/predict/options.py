"""`posenet predict`'s vocabularies and defaults, one home each, and nothing heavier than the standard
library: the command lines' help reads them without loading torch."""

FORMATS = ("bop", "speedplus")  # --format: the field's result files beside predictions.jsonl

# Pose-network runs per image in `posenet predict` and the Python Predictor: the box, then one re-crop.
# On 1,600 held-out corridor images the second pass beat the first from every box (the true one, noisy
# ones at IoU 0.5-0.8, two detectors') with the 40-minute network, and a third added nothing beyond the
# paired error (docs/benchmarks.md, "The sweep with a stronger network"). `posenet eval` stays at 1 pass,
# the protocol of the paper's tables, unless --passes says otherwise.
PREDICT_PASSES = 2

# below: the pose is flagged low_confidence, and the navigation filter takes it for no measurement (on
# held-out sequences those are the frames in eclipse, where the network gives its prior's guess)
LOW_CONFIDENCE = 0.5
