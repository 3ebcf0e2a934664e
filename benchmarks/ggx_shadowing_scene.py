"""What pbrt-v4's height-correlated GGX shadowing-masking does to a whole scene (issue 44: the
ggx_copper_80 cross-check), measured with Mitsuba 3 alone.

    .venv/bin/python benchmarks/ggx_shadowing_scene.py [-s ggx_copper_80] [--spp 256] [--passes 4]
                                                       [--pbrt-passes DIR]

The scene's GGX conductors are rendered by this project's ``sb_thin_film_conductor`` plugin with a
film of thickness 0 (exactly the bare conductor: exporters/mitsuba_plugins/thin_film_conductor.py)
twice with the same seeds: once with its own separable Smith term G1(i) G1(o) (the IR's, Mitsuba's
``roughconductor``), once with the height-correlated G2 = 1 / (1 + Lambda(i) + Lambda(o)) that
pbrt-v4 uses and offers alone (Heitz 2014, "Understanding the Masking-Shadowing Function in
Microfacet-Based BRDFs", JCGT 3(2), eq. 99; pbrt-v4 util/scattering.h
TrowbridgeReitzDistribution::G), with Lambda = 1 / G1 - 1 (Heitz 2014 eq. 43). Both sample the
visible normals the same way (the VNDF of G1(i)), so with one seed they trace the same paths and
differ only in the weight: G1(o) becomes G2 / G1(i). Their ratio is therefore measured far more
precisely than either image.

Each is rendered through the Mitsuba backend's own route (the writer, the CMF film of the IR's
colour, film_to_ir) and judged against the committed reference as a cross-check is
(batch/verdict/crosscheck.py ``judge``: block and scale tests, the diagnosis' uniform scale). The
separable run is the control (it must agree with the reference); the height-correlated run
predicts what pbrt-v4 should read. ``--pbrt-passes DIR``: pbrt-v4's passes of the same scene
kept by ``batch/make_references.py --crosscheck pbrt`` (references/.work/.crosscheck/pbrt/SCENE),
judged against the reference and against the height-correlated Mitsuba run.

Prints plain lines; writes nothing (a diagnostic: what it measured goes into docs/findings.md).
"""
import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import pkg_bootstrap  # noqa: E402

pkg_bootstrap.package()
pkg_bootstrap.single_threaded_blas()

from spectral_bench.batch.backends.mitsuba import backend as mb, spectral as spectral_film  # noqa: E402
from spectral_bench.batch.verdict import crosscheck as cc, references  # noqa: E402
from spectral_bench.exporters import mitsuba_writer  # noqa: E402


def plugin_class(height_correlated):
    """sb_thin_film_conductor with the Smith term chosen (see the module docstring)."""
    import drjit as dr
    from spectral_bench.exporters.mitsuba_plugins import thin_film_conductor as tf

    class Shadowed(tf.ThinFilmConductor):
        def _g(self, distr, wi, wo, m, g1_i=None):
            g1_i = distr.smith_g1(wi, m) if g1_i is None else g1_i
            g1_o = distr.smith_g1(wo, m)
            if not height_correlated:
                return g1_i * g1_o
            # Lambda = 1 / G1 - 1 (G1 = 1 / (1 + Lambda)); G2 = 1 / (1 + Lambda_i + Lambda_o)
            ok = (g1_i > 0) & (g1_o > 0)
            return dr.select(ok, 1.0 / (dr.rcp(dr.select(ok, g1_i, 1.0)) + dr.rcp(dr.select(ok, g1_o, 1.0)) - 1.0), 0.0)

        def _masked(self, d, g1_i, distr, wi, wo, m):
            return d * self._g(distr, wi, wo, m, g1_i)

        def _sample_weight(self, distr, wi, wo, m):
            g1_i = distr.smith_g1(wi, m)
            return self._g(distr, wi, wo, m, g1_i) / dr.select(g1_i > 0, g1_i, 1.0)  # VNDF: pdf carries G1(i)
    return Shadowed


def bare_conductors(scene):
    """The scene with every rough GGX conductor given a film of thickness 0 (the plugin's route)."""
    scene = json.loads(json.dumps(scene))
    n = 0
    for obj in scene["objects"]:
        b = obj.get("bsdf") or {}
        if b.get("type") == "conductor" and (b.get("roughness") or {}).get("distribution") == "ggx" \
                and b.get("thin_film") is None:
            b["thin_film"] = {"ior": 1.0, "thickness": 0.0, "ext_ior": 1.0}
            n += 1
    if not n:
        raise SystemExit(f"{scene['name']}: no rough GGX conductor to change")
    return scene


def render(xml, form, spp, seeds):
    """[(names, image)] of each seed, rendered with the Smith ``form``."""
    import mitsuba as mi
    from spectral_bench.exporters.mitsuba_plugins import thin_film_conductor as tf
    cls = plugin_class(form == "height-correlated")
    mi.register_bsdf(tf.PLUGIN_NAME, lambda props: cls(props))
    scene = mi.load_file(str(xml))
    out = []
    for seed in seeds:
        img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float64)
        out.append(mb.film_to_ir(["X", "Y", "Z"], img[..., :3], Path(xml).parent))
    return out


def as_reference(passes, spp, label):
    names = passes[0][0]
    stack = np.stack([p[1] for p in passes])
    mean = stack.mean(axis=0)
    stderr = stack.std(axis=0, ddof=1) / np.sqrt(len(passes))
    return references.Reference(list(names), mean.astype(np.float32), stderr.astype(np.float32),
                                {"spp": spp * len(passes), "passes": len(passes), "backend": label}, None)


def say(label, result):
    ratio = ", ".join(f"{c} {v[0]:.5f} +- {v[1]:.5f}" for c, v in (result.get("ratio") or {}).items() if v)
    t = result.get("test") or {}
    sc = t.get("scale_test") or {}
    det = result.get("detectable")
    print(f"{label}: {'agrees' if result.get('agrees') else 'DIFFERS'}; ratio {ratio}; block p_min {t.get('p_min'):.3g} "
          f"(threshold {t.get('threshold'):.3g}), z_max {t.get('z_max'):.2f}; scale test s "
          f"{[round(x, 5) for x in sc.get('s') or []]} +- {[round(x, 5) for x in sc.get('se') or []]}; "
          f"detects {cc.percent(det) if det else 'nothing'}", flush=True)
    for line in cc.difference_lines(result):
        print(f"    {line}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(prog="benchmarks/ggx_shadowing_scene.py", description=__doc__.splitlines()[0])
    ap.add_argument("-s", "--scene", default="ggx_copper_80")
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel per pass")
    ap.add_argument("--passes", type=int, default=4)
    ap.add_argument("--seed", type=int, default=5000)
    ap.add_argument("--pbrt-passes", type=Path, help="pbrt-v4's kept cross-check passes of the scene (a folder)")
    args = ap.parse_args(argv)
    import mitsuba as mi
    mi.set_variant("llvm_ad_spectral")
    from spectral_bench.batch import scene_sources
    ((_name, scene),) = scene_sources.load([str(ROOT / "golden" / "ir" / f"{args.scene}.json")])
    ref, bad = references.examine(references.REFERENCE_DIR, args.scene, references.fingerprint(scene))
    if ref is None or bad:
        raise SystemExit(f"{args.scene}: no usable reference: {bad}")
    seeds = [args.seed + k * 1000 for k in range(args.passes)]
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        xml = mitsuba_writer.write(bare_conductors(scene), Path(tmp) / "export")
        xml.write_text(spectral_film.cmf_xml(xml.read_text(), str(xml)))
        for form in ("separable", "height-correlated"):
            t = time.perf_counter()
            runs[form] = render(xml, form, args.spp, seeds)
            print(f"{form}: {args.passes} x {args.spp} spp, seeds {seeds}, {time.perf_counter() - t:.0f} s", flush=True)
    sep, hc = (as_reference(runs[f], args.spp, f"mitsuba-{f}") for f in ("separable", "height-correlated"))
    # the ratio of the two, pass by pass (same seeds: the same paths)
    r = np.stack([h[1].reshape(-1, 3).mean(axis=0) / s[1].reshape(-1, 3).mean(axis=0)
                  for s, h in zip(runs["separable"], runs["height-correlated"])])
    se = r.std(axis=0, ddof=1) / np.sqrt(len(r)) if len(r) > 1 else np.full(3, np.nan)
    print("height-correlated / separable, image mean, R G B: "
          + ", ".join(f"{m:.5f} +- {e:.5f}" for m, e in zip(r.mean(axis=0), se)), flush=True)
    h, w = sep.mean.shape[:2]
    q = np.stack([hh[1] / np.maximum(ss[1], 1e-12) for ss, hh in zip(runs["separable"], runs["height-correlated"])]).mean(0)
    for name, (ys, xs) in {"lower left": (slice(3 * h // 4, h), slice(0, w // 4)),
                           "lower right": (slice(3 * h // 4, h), slice(3 * w // 4, w)),
                           "centre": (slice(3 * h // 8, 5 * h // 8), slice(3 * w // 8, 5 * w // 8)),
                           "top": (slice(0, h // 4), slice(w // 4, 3 * w // 4))}.items():
        a = np.stack([hh[1][ys, xs].reshape(-1, 3).sum(0) / ss[1][ys, xs].reshape(-1, 3).sum(0)
                      for ss, hh in zip(runs["separable"], runs["height-correlated"])])
        print(f"  {name}: " + ", ".join(f"{m:.4f}" for m in a.mean(axis=0)), flush=True)
    del q
    for form, check in (("separable (control)", sep), ("height-correlated", hc)):
        say(f"Mitsuba, {form}, against the reference", cc.judge(ref, check, scene, "mitsuba", "llvm_ad_spectral"))
    if args.pbrt_passes:
        from spectral_bench.batch import make_references as mk
        count = len([p for p in args.pbrt_passes.glob("pass*") if (p / "done.json").is_file()])
        names, mean, stderr, _s, versions = mk.merge(args.pbrt_passes, count, tuple(ref.mean.shape[1::-1]))
        first = json.loads((args.pbrt_passes / "pass0" / "done.json").read_text())
        pbrt = references.Reference(names, mean, stderr, {"spp": int(first["spp"]) * count, "passes": count,
                                                          "backend": "pbrt"}, None)
        say("pbrt-v4 against the reference", cc.judge(ref, pbrt, scene, "pbrt", "spectral"))
        say("pbrt-v4 against Mitsuba with the height-correlated G", cc.judge(hc, pbrt, scene, "pbrt", "spectral"))
        say("pbrt-v4 against Mitsuba with the separable G", cc.judge(sep, pbrt, scene, "pbrt", "spectral"))
        # the reference times the measured per-pixel ratio height-correlated / separable: what
        # pbrt-v4 should read if the shadowing form is the whole difference
        num = np.sum([hh[1] for hh in runs["height-correlated"]], axis=0)
        den = np.sum([ss[1] for ss in runs["separable"]], axis=0)
        ratio = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
        predicted = references.Reference(ref.names, (ref.mean * ratio).astype(np.float32),
                                         (ref.stderr * ratio).astype(np.float32), ref.provenance, None)
        say("pbrt-v4 against the reference times the height-correlated / separable ratio",
            cc.judge(predicted, pbrt, scene, "pbrt", "spectral"))
        # the uniform scale that ratio amounts to in pbrt's own noise test (its scale test's
        # weights and blocks): the scale a known deviation's model must carry
        from spectral_bench.batch.verdict import compare
        v = references.judge_replacement(ref, pbrt, None, compare.min_samples_for(args.scene), None, keep=True)
        zt = v["_ztest"]
        ey, ex = compare.block_edges(h, zt.block), compare.block_edges(w, zt.block)
        n = compare.block_sums(np.ones((h, w, 1)), ey, ex)
        m_pred = compare.block_sums(ref.mean.astype(np.float64) * ratio, ey, ex) / n
        wgt = zt.weight
        s_pred = 1.0 + np.sum(wgt * (m_pred - zt.ref_block_mean), axis=(0, 1)) / np.sum(wgt * zt.ref_block_mean, axis=(0, 1))
        print("predicted scale-test s of pbrt-v4 against the reference (R, G, B): "
              + ", ".join(f"{x:.5f}" for x in np.ravel(s_pred)) + f"; block {zt.block} px", flush=True)
        ratios = (m_pred / np.where(zt.ref_block_mean > 0, zt.ref_block_mean, np.nan)).reshape(-1, 3)
        print("block ratios height-correlated / separable: min " + ", ".join(f"{x:.4f}" for x in np.nanmin(ratios, 0))
              + "; max " + ", ".join(f"{x:.4f}" for x in np.nanmax(ratios, 0)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
