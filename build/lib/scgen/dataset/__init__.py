"""The dataset on disk: its layout, the BOP files, the writer, splits, stats, validation, merge and
exports."""
