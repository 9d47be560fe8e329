"""The instrument models the virtual lab simulates (no heavy imports: the CLI reads these to parse).

Each role maps a simulated model to the :mod:`labkit.drivers` model that talks to it.
"""
from __future__ import annotations

#: 33500B models and their channel counts (33500B Series data sheet: 33511B/33521B one, 33512B/33522B two)
MODELS_33500B = {"33511B": 1, "33512B": 2, "33521B": 1, "33522B": 2}
#: DG1000Z models and their channel counts (all two-channel)
MODELS_DG1000Z = {"DG1022Z": 2, "DG1032Z": 2, "DG1062Z": 2}

FUNCGEN_MODELS = {**{m: "33500B" for m in MODELS_33500B}, **{m: "DG1000Z" for m in MODELS_DG1000Z},
                  "33220A": "33220A"}
SCOPE_MODELS = {"DSOX3024T": "InfiniiVision", "DSOX2024A": "InfiniiVision", "DS1104Z": "DS1000Z", "DS1074Z": "DS1000Z",
                "DS1054Z": "DS1000Z", "DS1202Z-E": "DS1000Z"}
#: oscilloscopes with two analog channels (the rest have four); only these DS1000Z have an EXT TRIG input
TWO_CHANNEL_SCOPES = ("DS1202Z-E",)
VIBROMETER_MODELS = {"OFV-5000": "OFV-5000", "OFV-3001": "OFV-3001"}
