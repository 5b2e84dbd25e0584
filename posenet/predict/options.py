"""`posenet predict`'s vocabularies and defaults, one home each, and nothing heavier than the standard
library: the command lines' help reads them without loading torch."""

FORMATS = ("bop", "speedplus")  # --format: the field's result files beside predictions.jsonl

# Pose-network runs per image in `posenet predict` and the Python Predictor: the box, then one re-crop.
# On 1,600 held-out corridor images the second pass beat the first from every box (the true one, noisy
# ones at IoU 0.5-0.8, two detectors') with the 40-minute network, and a third added nothing beyond the
# paired error (docs/benchmarks.md, "The sweep with a stronger network"). `posenet eval` stays at 1 pass,
# the protocol of the paper's tables, unless --passes says otherwise.
PREDICT_PASSES = 2

# A pass after the first runs only where the model's box at the pose before overlaps the box that pass
# cropped around by IoU < SAME_CROP_IOU (posenet.predict.recrop.next_crop); elsewhere the network would see
# nearly the crop it just saw. Chosen on held-out val images (300) as the lowest gate whose ADD@0.1d stays
# within one paired standard error of two passes for each network (a 40-minute and a 12-minute one) and
# box source (true, noisy, detected); on 600 held-out test images it skips a third of the second passes
# from the detectors' boxes with the 40-minute network and loses nothing against two passes (+0.3 ± 1.2,
# +0.8 ± 1.0 points; docs/benchmarks.md, "predict's second pass where it changes the crop").
SAME_CROP_IOU = 0.75

# below: the pose is flagged low_confidence, and the navigation filter takes it for no measurement (on
# held-out sequences those are the frames in eclipse, where the network gives its prior's guess)
LOW_CONFIDENCE = 0.5
