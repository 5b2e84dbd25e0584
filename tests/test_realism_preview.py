"""`scgen preview` writes one contact sheet with a tile per sample."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner
from PIL import Image

from scgen.cli import main


def test_preview_writes_one_contact_sheet(tmp_path):
    args = ["preview", "--out", str(tmp_path), "--n", "2", "--backend", "mitsuba", "--resolution", "160x120"]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    sheet = np.asarray(Image.open(tmp_path / "preview.png").convert("RGB"))
    assert sheet.shape[1] > 4 * 300 and sheet.shape[0] > 300  # a row of four tiles, two filled
    assert sheet[:, : sheet.shape[1] // 2].std() > 10  # the filled tiles are not blank
