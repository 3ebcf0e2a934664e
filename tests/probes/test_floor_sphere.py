"""The sphere-on-a-floor probe (issue 44 item 1, batch/verdict/probes/floor_sphere.py): Lambert's
projected solid angle of a clipped polygon against a seeded Monte Carlo integral and closed
cases; the probe judging the committed Mitsuba references of the four scenes (yellow_sphere_F8 and
the three fluorescent spheres on a floor) at reduced resolution, and failing planted errors (a
render 3 % brighter, the F8 illuminant swapped for D50) with its power below the planted size; the
registry choosing it for those four scenes only; the default run's label no longer "checked
against itself" for them."""
import copy

import numpy as np
import pytest

from conftest import ROOT
from spectral_bench.batch import exr
from spectral_bench.batch.report import results
from spectral_bench.batch.verdict import probes
from spectral_bench.batch.verdict.probes import floor_sphere

ON_FLOOR = ["yellow_sphere_F8", "fluorescent_sphere_D50_red", "fluorescent_sphere_mono_red",
            "fluorescent_sphere_mono_invisible"]
SIZE = 128  # the 512 px references box-averaged 4 x 4: the same scene's box-filtered 128 px image


# ---- the projected solid angle --------------------------------------------------------------------

def _square(half, z=0.0, cx=0.0, cy=0.0):
    return np.array([[cx - half, cy - half, z], [cx + half, cy - half, z], [cx + half, cy + half, z],
                     [cx - half, cy + half, z]])


def test_no_floor_in_the_hemisphere_leaves_the_whole_sky():
    """A point on top of the sphere sees nothing of the floor below its tangent plane: pi of sky."""
    g = floor_sphere.projected_solid_angle([[0, 0, 1.0]], [[0, 0, 1.0]], _square(20.0, -1.0))
    assert g[0] == 0.0


def test_an_infinite_floor_at_the_equator_is_half_the_hemisphere():
    """At the equator (normal horizontal), an unbounded floor fills the lower half: pi / 2. A floor
    of half-side 1e6 at 1 below misses it by about 1e-6 of pi."""
    g = floor_sphere.projected_solid_angle([[1.0, 0, 0]], [[1.0, 0, 0]], _square(1e6, -1.0))
    assert abs(g[0] - np.pi / 2) < 1e-5


def test_a_square_on_the_normal_matches_the_form_factor():
    """A square of half-side a at distance c, centred on the normal: four corner rectangles of the
    classical point-to-parallel-rectangle form factor (Howell's catalogue, C-11):
    F = 1/(2 pi) [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + B/sqrt(1+B^2) atan(A/sqrt(1+B^2))], G = pi F."""
    for a, c in ((0.5, 1.0), (2.0, 0.7), (10.0, 3.0)):
        ar = a / c
        f = (2 * ar / np.sqrt(1 + ar**2) * np.arctan(ar / np.sqrt(1 + ar**2))) / (2 * np.pi)
        g = floor_sphere.projected_solid_angle([[0, 0, c]], [[0, 0, -1.0]], _square(a))
        assert abs(g[0] - 4 * np.pi * f) < 1e-12 * np.pi


def test_clipped_polygons_match_a_seeded_monte_carlo_integral():
    """Points on a unit sphere resting on a floor of half-side 3 (so the floor is both finite and
    cut by the tangent plane): cosine-weighted directions (Malley) hitting the floor, times pi, is
    an unbiased estimate of G with a binomial standard error; the formula must lie within 5 of them,
    and the estimates resolve 1 % of pi (the size of an error the test claims to see)."""
    rng = np.random.default_rng(44)
    floor = _square(3.0, -1.0)
    n_dirs = 200_000
    clipped = 0
    for _ in range(12):
        nrm = rng.normal(size=3)
        nrm /= np.linalg.norm(nrm)
        p = nrm  # a point of the unit sphere at the origin, its normal
        # cosine-weighted directions about nrm
        u1, u2 = rng.random(n_dirs), rng.random(n_dirs)
        r, phi = np.sqrt(u1), 2 * np.pi * u2
        t1 = np.cross(nrm, [1.0, 0, 0] if abs(nrm[0]) < 0.9 else [0, 1.0, 0])
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(nrm, t1)
        d = (r * np.cos(phi))[:, None] * t1 + (r * np.sin(phi))[:, None] * t2 + np.sqrt(1 - u1)[:, None] * nrm
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (-1.0 - p[2]) / d[:, 2]
        x = p + np.where(t > 0, t, np.nan)[:, None] * d
        hits = (t > 0) & (np.abs(x[:, 0]) <= 3.0) & (np.abs(x[:, 1]) <= 3.0)
        share = hits.mean()
        se = np.pi * np.sqrt(max(share * (1 - share), 1.0 / n_dirs) / n_dirs)
        assert 5 * se < 0.01 * np.pi
        g = floor_sphere.projected_solid_angle([p], [nrm], floor)[0]
        assert abs(g - np.pi * share) <= 5 * se, (nrm, g, np.pi * share, se)
        heights = (floor - p) @ nrm
        clipped += bool((heights > 0).any() and (heights < 0).any())
    assert clipped >= 3  # the clipping itself was exercised


# ---- the probe on the committed references ---------------------------------------------------------

def _reduced(golden, name, radiance=None):
    scene = copy.deepcopy(golden[name])
    scene["render"]["width"] = scene["render"]["height"] = SIZE
    if radiance is not None:
        scene["environment"]["radiance"] = copy.deepcopy(radiance)
    names, img = exr.read_image(ROOT / "references" / f"{name}.exr")
    k = img.shape[0] // SIZE
    img = img.reshape(SIZE, k, SIZE, k, img.shape[-1]).mean(axis=(1, 3))
    return scene, names, img


def _floor_record(scene, names, image):
    recs = [r for r in probes.evaluate(scene, names, image, observers=("mitsuba3",)) if "on a floor" in r["name"]]
    assert len(recs) == 1, [r["name"] for r in recs]
    return recs[0]


@pytest.mark.parametrize("name", ON_FLOOR)
def test_references_lie_in_their_intervals_and_a_3_percent_brighter_render_fails(golden, name):
    """Mitsuba's reference inside [lo, hi] where the bound leaves power; the same image 3 % brighter
    outside, and the probe's power (the interval's width plus the shift beyond it that fails with
    90 % power, in its best channel) below those 3 %: any render 3 % off the truth fails."""
    scene, names, img = _reduced(golden, name)
    rec = _floor_record(scene, names, img)
    assert rec["pass"] is True, rec
    assert rec["pixels"] >= 50
    assert rec["width"] + rec["detectable"] < 0.03, rec
    bright = _floor_record(scene, names, img * 1.03)
    assert bright["pass"] is False, bright
    dark = _floor_record(scene, names, img / 1.03)
    assert dark["pass"] is False, dark


def test_the_f8_sphere_under_a_swapped_illuminant_fails(golden):
    """yellow_sphere_F8's render judged as if lit by D50 (fluorescent_sphere_D50_red's sky): the
    intervals move by far more than the probe's power, and the render falls outside."""
    d50 = golden["fluorescent_sphere_D50_red"]["environment"]["radiance"]
    scene, names, img = _reduced(golden, "yellow_sphere_F8", d50)
    rec = _floor_record(scene, names, img)
    right = _floor_record(*_reduced(golden, "yellow_sphere_F8"))
    moved = np.abs(np.array(rec["expected"]) / np.array(right["expected"]) - 1)[:2]  # R, G
    assert rec["detectable"] + rec["width"] < moved.max(), (rec, moved)
    assert rec["pass"] is False, rec


# ---- the registry and the label -------------------------------------------------------------------

def test_the_registry_picks_the_probe_for_the_spheres_on_a_floor_only(golden):
    assert floor_sphere.sphere_on_floor in probes.PROBES
    chosen = sorted(n for n, sc in golden.items() if floor_sphere.applies(sc) is not None)
    assert chosen == sorted(ON_FLOOR)
    # the lone sphere (no floor) and a plate over a floor are not its business
    for other in ("fluorescent_sphere_lone", "ggx_copper_50", "macbeth_chart_D65"):
        sc = copy.deepcopy(golden[other])
        sc["render"]["width"] = sc["render"]["height"] = 16
        recs = probes.evaluate(sc, ["R", "G", "B"], np.zeros((16, 16, 3), dtype=np.float32))
        assert not [r for r in recs if "on a floor" in r["name"]]


def test_a_run_judged_by_the_probe_is_not_checked_against_itself(golden):
    """The label's rule (batch/report/results.py): a judged run with a measured probe is not
    "checked against itself", even against Mitsuba's own reference."""
    scene, names, img = _reduced(golden, "yellow_sphere_F8")
    rec = _floor_record(scene, names, img)
    run = {"status": "ok", "backend": "mitsuba", "reference": {"backend": "mitsuba"}, "probes": [rec]}
    assert results.probes_measured(run) == (1, 1)
    assert not results.checked_against_itself(run)
    assert results.checked_against_itself({**run, "probes": []})


def test_the_run_reports_the_probe_s_power(golden):
    """metrics.json's ``detectable`` names the probe with its width plus its figure beyond the
    interval (batch/verdict/judge.py): the smallest change of the truth that surely fails."""
    from spectral_bench.batch.verdict import judge
    rec = _floor_record(*_reduced(golden, "yellow_sphere_F8"))
    det = judge.detectable(None, [rec])
    assert det["probes"][rec["name"]] == pytest.approx(rec["width"] + rec["detectable"])
    assert det["probes"][rec["name"]] < 0.03


def test_the_bound_on_every_radiance_is_the_sky_without_fluorescence_and_above_it_with(golden):
    """B (the floor's upper bound over rho_f) is L itself for the yellow sphere (albedos <= 1), so
    the floor's upper spectrum is K[rho_f L]; with re-radiation into the red under a 450 nm sky
    (L = 0 there) B must exceed L where the sphere emits, else the floor's red would be bounded by 0."""
    def spectra_of(name):
        sc = golden[name]
        si, fi = floor_sphere.applies(sc)
        shares = [(big, s) for big, s, _ in floor_sphere._squares(sc, si, fi)]
        return floor_sphere._spectra(sc["objects"][si]["bsdf"], sc["objects"][fi]["bsdf"],
                                     sc["environment"]["radiance"], shares)
    a, u_lo, u_hi, ups, q = spectra_of("yellow_sphere_F8")
    assert q < 1 and np.allclose(u_hi, u_lo, rtol=1e-12, atol=0)
    a, u_lo, u_hi, ups, q = spectra_of("fluorescent_sphere_mono_red")
    assert q < 1
    wl = np.arange(360, 831)
    red = (wl >= 620) & (wl <= 680)
    assert np.all(u_hi[red] > u_lo[red]) and np.all(u_hi >= u_lo - 1e-15)
