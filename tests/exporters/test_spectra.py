import numpy as np
import pytest

from spectral_bench.exporters import spectra


def test_named_illuminant_is_one_at_560nm_times_scale():
    v = spectra.evaluate({"type": "named", "name": "cie_d65", "scale": 4.0}, [560.0])
    assert v[0] == pytest.approx(4.0)


def test_named_d65_matches_cie_table_shape():
    # CIE D65 at 5 nm: 460 nm is 117.812, 560 nm is 100.0 (CIE 15:2004 table)
    v = spectra.evaluate({"type": "named", "name": "cie_d65"}, [460.0])
    assert v[0] == pytest.approx(1.17812, rel=1e-5)


def test_blackbody_normalised_and_shaped_by_planck():
    s = {"type": "blackbody", "temperature": 3000.0, "scale": 2.0}
    v = spectra.evaluate(s, [560.0, 700.0])
    assert v[0] == pytest.approx(2.0)
    assert v[1] > v[0]  # a 3000 K body rises towards the red (Wien peak ~966 nm)


def test_sampled_padding_covers_renderer_range_with_edge_values():
    s = {"type": "sampled", "wavelengths": [400.0, 700.0], "values": [0.2, 0.8]}
    wl, vals = spectra.tabulate(s)
    assert wl[0] == spectra.LAMBDA_MIN and wl[-1] == spectra.LAMBDA_MAX
    assert vals[0] == pytest.approx(0.2) and vals[-1] == pytest.approx(0.8)
    assert spectra.evaluate(s, [550.0])[0] == pytest.approx(0.5)


def test_named_table_tabulated_over_full_range():
    wl, vals = spectra.tabulate({"type": "named", "name": "cie_d65", "scale": 1.0})
    assert wl[0] == 360 and wl[-1] == 830 and np.all(vals > 0)


@pytest.mark.parametrize("spec, field", [
    ({"type": "constant", "value": float("nan")}, "s.value"),
    ({"type": "constant", "value": -1.0}, "s.value"),
    ({"type": "named", "name": "cie_d66"}, "s.name"),
    ({"type": "blackbody", "temperature": 0.0}, "s.temperature"),
    ({"type": "sampled", "wavelengths": [500.0, 400.0], "values": [1.0, 1.0]}, "s.wavelengths"),
    ({"type": "rainbow"}, "s.type"),
])
def test_check_names_the_bad_field(spec, field):
    problems = list(spectra.check(spec, "s"))
    assert problems and problems[0][0] == field
