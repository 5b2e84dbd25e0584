"""The camera presets' sensors measured by photon transfer, beside their configured values.

    python benchmarks/photon_transfer.py

Flat fields through scgen's sensor model (16-bit ADC, no dark current or defects, so the read noise
is resolved), fitted as EMVA 1288 does (scgen.render.camera.characterise.photon_transfer).
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from harness import parser, run_script

from scgen.render.camera.characterise import photon_transfer
from scgen.render.camera.sensor import conversion_gain
from scgen.scenes.config.camera import preset_settings

CASES = (("default", 1.0), ("default", 4.0), ("default", 16.0), ("speedplus", 1.0), ("speedplus", 8.0))


def run(args: argparse.Namespace) -> None:
    header = ("preset", "gain", "K set", "K fit", "err", "read set", "read fit", "err")
    print("{:10} {:>5} {:>8} {:>8} {:>6} {:>9} {:>9} {:>6}".format(*header))
    for preset, gain in CASES:
        flat_field = {"adc_bits": 16, "dark_current_e_s": 0.0, "hot_pixel_frac": 0.0, "dead_pixel_frac": 0.0}
        sensor = replace(preset_settings(preset).sensor, **flat_field)
        k_set, read_set = conversion_gain(sensor, gain), sensor.read_noise_e
        k_fit, read_fit = photon_transfer(sensor, gain)
        print(f"{preset:10} {gain:5.1f} {k_set:8.3f} {k_fit:8.3f} {100 * (k_fit / k_set - 1):5.1f}% "
              f"{read_set:9.2f} {read_fit:9.2f} {100 * (read_fit / read_set - 1):5.1f}%")  # fmt: skip


if __name__ == "__main__":
    run_script(run, parser(__doc__).parse_args())
