"""Which GGX each renderer implements: a rough conductor plane under a uniform environment of
radiance 1 reflects exactly its directional albedo E(theta_o) = integral f(wi, wo) cos(theta_i) dwi,
computed here by quadrature (numpy, no renderer) for three shadowing-masking terms:
  separable Smith G1(wi) G1(wo) (Walter et al. 2007, eq. 23; the IR's GGX, Mitsuba 3's),
  height-correlated Smith 1 / (1 + Lambda(wi) + Lambda(wo)) (Heitz 2014, eq. 99; Cycles'),
  Schlick's G (c / (c (1 - a^2) + a^2) per direction; LuxCore's SchlickDistribution_G),
with the exact conductor Fresnel and GGX's D. Each renderer renders the plane through the
benchmark's own backends (a camera with a 2-degree field of view at theta_o from the normal;
constant eta/k, so the RGB reduction is exact), and its mean over the image (ratio to the
environment) is compared with each prediction in standard errors.

    .venv/bin/python benchmarks/rgb_microfacet_check.py [--spp 1024] [--write]
    .venv/bin/python benchmarks/rgb_microfacet_check.py --smoke --spp 4 --passes 2   # seconds

--write puts the table in benchmarks/RGB.md (section "Which GGX each renderer implements").
"""
import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

ETA, K = 0.2, 3.0


def fresnel(c, eta=ETA, k=K):
    from spectral_bench.exporters.rgb_reduction import fresnel_conductor
    return fresnel_conductor(c, eta, k)


def albedo(theta_o_deg, alpha, shadowing, n_theta=3000, n_phi=720):
    """Directional albedo by quadrature over the half-vector (dwi = 4 (wo.h) dwh)."""
    to = math.radians(theta_o_deg)
    wo = np.array([math.sin(to), 0.0, math.cos(to)])
    # theta_h on a grid dense where D is: tan(theta_h) = alpha * tan(u), u uniform in [0, pi/2)
    u = (np.arange(n_theta) + 0.5) / n_theta * (math.pi / 2)
    th = np.arctan(alpha * np.tan(u))
    dth = alpha / np.cos(u) ** 2 / (1 + (alpha * np.tan(u)) ** 2) * (math.pi / 2 / n_theta)
    ph = (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi
    T, P = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1)
    oh = h @ wo
    wi = 2 * oh[..., None] * h - wo
    ci, co, ch = wi[..., 2], wo[2], h[..., 2]
    a2 = alpha * alpha
    d = a2 / (math.pi * (ch**2 * (a2 - 1) + 1) ** 2)
    lam = lambda c: (-1 + np.sqrt(1 + a2 * np.maximum(1 / np.maximum(c, 1e-12) ** 2 - 1, 0))) / 2  # noqa: E731
    if shadowing == "separable":
        g = 1 / (1 + lam(ci)) / (1 + lam(co))
    elif shadowing == "height-correlated":
        g = 1 / (1 + lam(ci) + lam(co))
    else:  # LuxCore: Schlick with r = alpha^2
        sg = lambda c: c / (c * (1 - a2) + a2)  # noqa: E731
        g = sg(np.abs(ci)) * sg(abs(co))
    f = fresnel(np.clip(oh, 0, 1)) * d * g / (4 * np.maximum(ci, 1e-12) * co)
    integrand = np.where((ci > 0) & (oh > 0), f * ci * 4 * oh, 0.0) * np.sin(T)
    return float(np.sum(integrand * dth[:, None]) * (2 * math.pi / n_phi))


def scene(theta_o_deg, alpha, size=16):
    from spectral_bench.exporters import ir
    to = math.radians(theta_o_deg)
    pos = 5.0 * np.array([0.0, -math.sin(to), math.cos(to)])
    z = pos / np.linalg.norm(pos)  # camera looks down -z
    x = np.array([1.0, 0.0, 0.0])
    y = np.cross(z, x)
    cam = np.eye(4)
    cam[:3, 0], cam[:3, 1], cam[:3, 2], cam[:3, 3] = x, y, z, pos
    sc = {"format": ir.FORMAT, "version": ir.VERSION, "name": "ggx_albedo", "case": "custom", "needs": [],
          "render": {"spp": 64, "width": size, "height": size, "max_depth": 64, "filter": "box", "integrator": "path"},
          "camera": {"to_world": cam.tolist(), "fov": 2.0, "fov_axis": "x"},
          "environment": {"type": "uniform", "radiance": {"type": "constant", "value": 1.0}},
          "objects": [{"name": "plate", "shape": {"type": "rectangle", "to_world": np.diag([50.0, 50.0, 1.0, 1.0]).tolist()},
                       "bsdf": {"type": "conductor", "eta": {"type": "constant", "value": ETA},
                                "k": {"type": "constant", "value": K},
                                "roughness": {"distribution": "ggx", "alpha": alpha}}, "emitter": None}]}
    sc["needs"] = ir.derived_needs(sc)
    return sc


def measure(backend, sc, spp, passes, tmp):
    from spectral_bench.batch import exr
    from spectral_bench.exporters import colorimetry
    mode, why = backend.mode_for(sc)
    if mode is None:
        return None, None, why
    path = backend.export(sc, Path(tmp) / backend.name / "export")
    backend.render(path, mode, spp, Path(tmp) / backend.name / "r.exr", passes=passes, seed=7)
    _, img, se = exr.read_image_and_stderr(Path(tmp) / backend.name / "r.exr")
    env = colorimetry.xyz_to_srgb(colorimetry.spectrum_xyz({"type": "constant", "value": 1.0}))
    ratio = img[..., :3] / env
    se_ratio = se[..., :3] / env
    mean = float(ratio.mean())
    sem = float(np.sqrt((se_ratio**2).sum()) / se_ratio.size)
    return mean, sem, ""


def main(argv=None):
    pkg_bootstrap.package()
    from spectral_bench.batch import backends
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=1024)
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--smoke", action="store_true", help="one angle and roughness (45, 0.2); not recorded")
    ap.add_argument("--write", action="store_true")
    args = ap.parse_args(argv)
    rows = ["| theta_o | alpha | separable (Mitsuba, IR) | height-correlated | Schlick G (LuxCore) | renderer | measured | z vs separable | z vs height-corr. | z vs Schlick |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for theta, alpha in ((45, 0.2), (45, 0.5), (75, 0.2), (75, 0.5))[:1 if args.smoke else None]:
        pred = {s: albedo(theta, alpha, s) for s in ("separable", "height-correlated", "schlick")}
        with tempfile.TemporaryDirectory() as tmp:
            for name in ("mitsuba", "cycles", "luxcore"):
                b = backends.get(name)
                if not b.availability()[0]:
                    continue
                m, se, why = measure(b, scene(theta, alpha), args.spp, args.passes, tmp)
                z = {s: (m - p) / se for s, p in pred.items()} if m is not None else {}
                rows.append(f"| {theta} | {alpha} | {pred['separable']:.4f} | {pred['height-correlated']:.4f} | "
                            f"{pred['schlick']:.4f} | {name} | " + (f"{m:.4f} +- {se:.4f} | {z['separable']:+.1f} | "
                            f"{z['height-correlated']:+.1f} | {z['schlick']:+.1f} |" if m is not None else f"{why} | | | |"))
                print(rows[-1], flush=True)
    text = "\n".join(rows)
    print(text)
    if args.write and not args.smoke:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from record import replace_section
        replace_section(Path(__file__).resolve().parent / "RGB.md", "Which GGX each renderer implements",
                        f"A rough conductor (eta {ETA}, k {K}) under a uniform environment, {args.spp} spp, "
                        f"{args.passes} passes (`benchmarks/rgb_microfacet_check.py --write`): the measured albedo "
                        f"against three closed forms, in the render's own standard errors.\n\n{text}")


if __name__ == "__main__":
    main()
