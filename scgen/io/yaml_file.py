"""YAML as a user writes numbers: `1e-3` and `1E-3` are floats, as in YAML 1.2 and every config's docs.

PyYAML follows YAML 1.1, whose floats need a dot and a signed exponent, so `lr: 1e-3` reads as the string
'1e-3'. `load_yaml` is safe_load plus YAML 1.2's float form; every YAML config (scgen's, posenet's, the
detector's) is read through it. Integers and everything else resolve as before.
"""

from __future__ import annotations

import re
from typing import Any

import yaml

# how a number is written, for the message of a value of the wrong type
NUMBER_FORM = "a number such as 0.001 or 1e-3"


class _Yaml12FloatLoader(yaml.SafeLoader):
    """SafeLoader that also reads YAML 1.2's exponent floats (1e-3, 1E3, 2.5e3, .5e-2)."""


# after YAML 1.1's resolvers (an int or a dotted float resolves as before); only an exponent is new
_Yaml12FloatLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"),
)


def load_yaml(text: str) -> Any:
    """The document in `text`, as yaml.safe_load reads it but with YAML 1.2's floats."""
    return yaml.load(text, Loader=_Yaml12FloatLoader)  # a SafeLoader: no arbitrary objects
