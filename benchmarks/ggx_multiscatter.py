"""Cycles on the GGX white furnaces (issue 41 item 2): how much of single scattering's missing
energy 1 - E each Cycles BSDF gives back, against GGX alpha.

    .venv/bin/python benchmarks/ggx_multiscatter.py [--spp 128] [--passes 2] [--write]

For each furnace_ggx_* scene (golden/ir: the scene as the runner exports it) the Cycles export is
built exactly as ``-r cycles`` builds it (batch/backends/cycles/worker.py ``build``: a Metallic BSDF,
Physical Conductor, eta 0 k 1, GGX, single scattering) and rendered in three variants, in this
process (bpy):

- "GGX": the export as it is (what ``-r cycles`` renders);
- "Multiscatter GGX": the same Metallic BSDF with distribution MULTI_GGX;
- "Principled": a Principled BSDF (Cycles' default distribution, Multiscatter GGX), Metallic 1,
  Base Color and Specular Tint white (F0 = F82 = 1: Fresnel 1), Roughness sqrt(alpha) as the export's.

Each render is judged by the white-furnace probe (batch/verdict/probes/white_furnace.py) and the
diagnosis's two models (batch/verdict/diagnosis/materials.py): "multiple scattering" (the render as
E + s (1 - E), Kulla and Conty 2017) and "height-correlated Smith". The table gives per alpha and
variant: the region's measured light over single scattering's (separable Smith, the IR's), the
fitted share s and whether each model fully explains the render. ``--write`` records it in
benchmarks/GGX_MULTISCATTER.md (date, machine, load)."""
import argparse
import datetime
import json
import os
import platform
import sys
import tempfile
import types
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import pkg_bootstrap  # noqa: E402

ROOT = pkg_bootstrap.ROOT
SCENES = ["furnace_ggx_010", "furnace_ggx_030", "furnace_ggx_060", "furnace_ggx_100"]
VARIANTS = ("GGX", "Multiscatter GGX", "Principled")


def variant_blend(blend, variant, out):
    """``blend`` with its conductor's BSDF changed to ``variant``, saved as ``out``."""
    import bpy
    bpy.ops.wm.open_mainfile(filepath=str(blend), use_scripts=False)
    for mat in bpy.data.materials:
        if not mat.node_tree:
            continue
        nt = mat.node_tree
        for node in [n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfMetallic"]:
            if variant == "Multiscatter GGX":
                node.distribution = "MULTI_GGX"
            elif variant == "Principled":
                p = nt.nodes.new("ShaderNodeBsdfPrincipled")
                p.inputs["Metallic"].default_value = 1.0
                p.inputs["Base Color"].default_value = (1.0, 1.0, 1.0, 1.0)
                p.inputs["Specular Tint"].default_value = (1.0, 1.0, 1.0, 1.0)
                p.inputs["Roughness"].default_value = node.inputs["Roughness"].default_value
                for link in list(node.outputs[0].links):
                    nt.links.new(p.outputs[0], link.to_socket)
                nt.nodes.remove(node)
    bpy.ops.wm.save_as_mainfile(filepath=str(out), compress=True)


def measure(name, spp, passes, tmp):
    from spectral_bench.batch import exr
    from spectral_bench.batch.backends.cycles import worker
    from spectral_bench.batch.verdict import probes
    from spectral_bench.batch.verdict import diagnosis
    from spectral_bench.batch.verdict.diagnosis import materials
    from spectral_bench.exporters import rgb_scene
    scene = json.loads((ROOT / "golden" / "ir" / f"{name}.json").read_text())
    from spectral_bench.batch.backends.cycles.backend import CyclesBackend
    rgb = rgb_scene.build(scene, CyclesBackend.distributions, light_types=CyclesBackend.light_types)
    base = Path(tmp) / f"{name}.blend"
    worker.build(rgb, base)
    rows = []
    for variant in VARIANTS:
        blend = Path(tmp) / f"{name}_{variant.replace(' ', '_')}.blend"
        variant_blend(base, variant, blend)
        out = Path(tmp) / f"{name}_{variant.replace(' ', '_')}.exr"
        info = worker.render(argparse.Namespace(blend=str(blend), mode="rgb", spp=spp, passes=passes, seed=0,
                                                out=str(out), result=str(out.with_suffix(".json"))))
        names, img, se = exr.read_image_and_stderr(out)
        rec = next(p for p in probes.evaluate(scene, names, img, stderr=se, passes=passes)
                   if " white furnace " in p["name"])
        ev = types.SimpleNamespace(entry={"probes": [rec]})
        ms = materials._multiple_scattering(ev)
        hc = materials._height_correlated_furnace(ev)
        # the whole diagnosis, as the runner ranks it (probe evidence only: no reference here)
        entry = {"scene": name, "backend": "cycles", "mode": "rgb", "probes": [rec]}
        found = diagnosis.diagnose(diagnosis.Evidence(entry, scene, names, img, se, passes))
        rows.append({"scene": name, "alpha": rec["alpha"], "variant": variant, "pass": rec["pass"],
                     "gain": ms.values[1], "gain_se": ms.se[1], "s": ms.values[0], "s_se": ms.se[0],
                     "ms_fully": ms.fully, "hc_fully": hc.fully, "missing": 100 * (1 - rec["mean_albedo"][0]),
                     "missing_hc": 100 * (1 - rec["mean_albedo_other"][0]),
                     "diagnosis": found["text"], "detectable": rec["detectable"], "time_s": round(info["time_s"], 2), "blender": info["versions"]["blender"]})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def table(rows):
    lines = ["| alpha | 1 - E (separable; height-correlated), region % | Cycles BSDF | region over single scattering % "
             "| kept share s of 1 - E | probe | diagnosis (the runner's ranking) |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['alpha']:g} | {r['missing']:.2f}; {r['missing_hc']:.2f} | {r['variant']} | "
                     f"{r['gain']:+.2f} +- {r['gain_se']:.2f} | {r['s']:.3f} +- {r['s_se']:.3f} | "
                     f"{'pass' if r['pass'] else 'fail'} | {r['diagnosis'] if not r['pass'] else 'nothing failed'} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--passes", type=int, default=2)
    ap.add_argument("--write", action="store_true")
    ap.add_argument("--scene", action="append", choices=SCENES, help="only this scene (repeatable)")
    ap.add_argument("--json", help="also write the rows to this file")
    args = ap.parse_args(argv)
    pkg_bootstrap.package()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.scene or SCENES:
            rows += measure(name, args.spp, args.passes, tmp)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    text = table(rows)
    print(text)
    if args.write:
        load = os.getloadavg()
        head = (f"# Cycles' GGX on the white furnaces\n\n`benchmarks/ggx_multiscatter.py --spp {args.spp} --passes "
                f"{args.passes}`, {datetime.date.today().isoformat()}, Blender {rows[0]['blender']}, "
                f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
                f"{load[0]:.1f} at the end (shared with other sessions). Each scene 128 x 128; the region: "
                "the sphere's judged pixels (cos theta_o >= 0.2).\n\n")
        (ROOT / "benchmarks" / "GGX_MULTISCATTER.md").write_text(head + text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
