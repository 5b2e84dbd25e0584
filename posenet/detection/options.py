"""The detector's defaults that the command lines show, torch-free: their help reads them without loading
torch or torchvision."""

# predict's default score floor (--min-score): a best box scoring less is no detection. FCOS scores a best
# box in any image; measured with the cpu preset trained 42 steps (6 min) on the tests' 24-image set, blank
# 320x240 images (black, mid-grey, noise) score 0.18-0.24, boxes that find the target (IoU >= 0.5) 0.67-0.74
# and boxes beside it 0.28-0.63 (docs/posenet.md, "The score floor")
MIN_SCORE = 0.5
