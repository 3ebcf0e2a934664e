"""Regenerate exporters/data/cie_illuminants.json from colour-science.

Source: colour-science 0.4.6, ``colour.SDS_ILLUMINANTS`` (CIE 15:2004 / CIE S 014-2
tables, 5 nm). Values are kept raw (CIE convention, 100 at 560 nm for the D series and A);
the IR's normalisation (1 at 560 nm) is applied in exporters/spectra.py, not here.

    .venv/bin/python scripts/generate_spectral_data.py
"""
import json
from pathlib import Path

import colour

NAMES = ["A", "D50", "D55", "D65", "D75", "E", "FL2", "FL7", "FL11"]


def main():
    out = {"source": f"colour-science {colour.__version__}, colour.SDS_ILLUMINANTS (CIE 15:2004 tables)",
           "illuminants": {}}
    for name in NAMES:
        sd = colour.SDS_ILLUMINANTS[name]
        out["illuminants"]["cie_" + name.lower()] = {
            "wavelengths": [float(w) for w in sd.wavelengths],
            "values": [round(float(v), 6) for v in sd.values],
        }
    path = Path(__file__).resolve().parents[1] / "exporters" / "data" / "cie_illuminants.json"
    path.write_text(json.dumps(out, indent=1) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()
