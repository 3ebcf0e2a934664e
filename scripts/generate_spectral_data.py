"""Regenerate the spectral data files in exporters/data/ from colour-science.

Sources (colour-science 0.4.6):
- cie_illuminants.json: ``colour.SDS_ILLUMINANTS`` (CIE 15:2004 tables, 5 nm), raw (100 at
  560 nm for the D series and A); the IR's normalisation (1 at 560 nm) is applied in
  exporters/spectra.py, not here.
- colorchecker_n_ohta.json: ``colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]``, the 24
  ColorChecker patches' reflectances measured by N. Ohta (380-780 nm, 5 nm).
- cie_1931_2deg_cmfs.json: ``colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]``
  (360-830 nm, 1 nm), used by the analytic probes.
- conductors.json: the complex IOR (eta, k) of the IR's named conductors, Mitsuba 3's own tables
  (mitsuba 3.9.1, mitsuba/data/ior/<name>.eta.spd and .k.spd, wavelength in nm; their headers name
  their sources), so that every writer and the probes use the data Mitsuba renders with.

    .venv/bin/python scripts/generate_spectral_data.py
"""
import json
import re
import sys
from pathlib import Path

import colour

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

ILLUMINANTS = ["A", "D50", "D55", "D65", "D75", "E", "FL2", "FL7", "FL8", "FL11"]
DATA = Path(__file__).resolve().parents[1] / "exporters" / "data"


def table(sd, digits=6):
    return {"wavelengths": [float(w) for w in sd.wavelengths], "values": [round(float(v), digits) for v in sd.values]}


def patch_name(label):
    """'white 9.5 (.05 D)' -> 'colorchecker_white_9_5'."""
    label = re.sub(r"\s*\(.*\)", "", label)
    return "colorchecker_" + re.sub(r"[^a-z0-9]+", "_", label.lower()).strip("_")


def write(name, data):
    path = DATA / name
    path.write_text(json.dumps(data, indent=1) + "\n")
    print("wrote", path)


def main():
    src = f"colour-science {colour.__version__}"
    write("cie_illuminants.json", {
        "source": f"{src}, colour.SDS_ILLUMINANTS (CIE 15:2004 tables)",
        "illuminants": {"cie_" + n.lower(): table(colour.SDS_ILLUMINANTS[n]) for n in ILLUMINANTS}})
    cc = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]
    write("colorchecker_n_ohta.json", {
        "source": f"{src}, colour.SDS_COLOURCHECKERS['ColorChecker N Ohta'] (N. Ohta's measurements)",
        "order": [patch_name(k) for k in cc],
        "labels": {patch_name(k): k for k in cc},
        "reflectances": {patch_name(k): table(sd) for k, sd in cc.items()}})
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    write("cie_1931_2deg_cmfs.json", {
        "source": f"{src}, colour.MSDS_CMFS['CIE 1931 2 Degree Standard Observer']",
        "wavelengths": [float(w) for w in cmfs.wavelengths],
        "x_bar": [round(float(v), 8) for v in cmfs.values[:, 0]],
        "y_bar": [round(float(v), 8) for v in cmfs.values[:, 1]],
        "z_bar": [round(float(v), 8) for v in cmfs.values[:, 2]]})
    write("conductors.json", conductors())


def read_spd(path):
    rows = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.lstrip().startswith("#")]
    return {"wavelengths": [float(r[0]) for r in rows], "values": [float(r[1]) for r in rows]}


def conductors():
    import mitsuba
    pkg_bootstrap.package()
    from spectral_bench.exporters.spectra import NAMED_CONDUCTORS
    folder = Path(mitsuba.__file__).parent / "data" / "ior"
    return {"source": f"mitsuba {mitsuba.__version__}, mitsuba/data/ior/<name>.eta.spd and <name>.k.spd (nm)",
            "conductors": {n: {"eta": read_spd(folder / f"{n}.eta.spd"), "k": read_spd(folder / f"{n}.k.spd")}
                           for n in NAMED_CONDUCTORS}}


if __name__ == "__main__":
    main()
