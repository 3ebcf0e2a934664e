"""Mitsuba 3 XML writer: IR scene -> folder with scene.xml, meshes/*.ply and spectra/*.spd.

The folder loads with ``mitsuba scene.xml`` or ``mi.load_file`` unchanged. Sample count,
seed and max depth are XML defaults ($spp, $seed, $max_depth) so a caller may override them.

Fluorescent scenes (the IR's ``needs`` has "fluorescence") use this project's Python plugins:
each fluorescent diffuse BSDF becomes ``sb_fluorescent_diffuse`` with its re-radiation table in
fluorescence/<object>.txt (exporters/fluorescence.py), the integrator is ``sb_fluorescent_path``
instead of ``path``, and every spectrum is tabulated from 300 nm (the re-radiation's lower end)
rather than 360 nm, so that light at UV excitation wavelengths is the scene's. Every other scene
keeps the stock ``path`` integrator and 360-830 nm tables.
"""
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from . import camera_filter, dispersion, fluorescence, ir, mesh_io, mitsuba_plugins, names, spectra, textures

# Blender/OpenGL cameras look down -Z with +Y up; Mitsuba's look down +Z with +X to the
# image's left. Mitsuba to_world = IR to_world @ diag(-1, 1, -1).
_CAMERA_FLIP = np.diag([-1.0, 1.0, -1.0, 1.0])
THIN_FILM_PLUGIN = "sb_thin_film_conductor"  # a conductor with bsdf.thin_film
DISPERSIVE_PLUGIN = "sb_dispersive_dielectric"  # exporters/mitsuba_plugins/dispersive_dielectric.py


def _matrix_text(m):
    return " ".join(repr(float(x)) for x in np.asarray(m, dtype=np.float64).reshape(-1))


def _transform(parent, m):
    t = ET.SubElement(parent, "transform", name="to_world")
    ET.SubElement(t, "matrix", value=_matrix_text(m))


class _Writer:
    def __init__(self, scene, out_dir):
        self.scene = scene
        self.out = Path(out_dir)
        self.files = []
        self.plugins = set()  # this project's Python plugins the scene uses (exporters/mitsuba_plugins)
        self.fluorescent = "fluorescence" in ir.derived_needs(scene)
        self.spectra_from = fluorescence.FLUORESCENT_SPECTRA_FROM if self.fluorescent else spectra.LAMBDA_MIN

    def spectrum(self, parent, name, spec, stem):
        if spectra.is_constant(spec):
            ET.SubElement(parent, "spectrum", name=name, value=repr(float(spec["value"])))
            return
        wl, vals = spectra.tabulate(spec, lo=self.spectra_from)
        rel = f"spectra/{stem}.spd"
        path = self.out / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(f"{w:.6g} {v:.9g}\n" for w, v in zip(wl, vals)))
        self.files.append(path)
        ET.SubElement(parent, "spectrum", name=name, filename=rel)

    def reflectance(self, node, key, obj):
        """A diffuse albedo: its spectrum, or with a reflectance_texture a bitmap of linear sRGB
        (exporters/textures.py) that the spectral variants uplift texel by texel with Jakob and
        Hanika's coefficients (``raw`` stays false: true would skip the uplift)."""
        b = obj["bsdf"]
        tex = b.get("reflectance_texture")
        if tex is None:
            self.spectrum(node, key, b["reflectance"], f"{names.file_stem(obj['name'])}_reflectance")
            return
        rel = textures.write_linear(tex, obj["name"], self.scene.get("_base_dir"), self.out)
        self.files.append(self.out / rel)
        bitmap = ET.SubElement(node, "texture", type="bitmap", name=key)
        ET.SubElement(bitmap, "string", name="filename", value=rel)
        ET.SubElement(bitmap, "string", name="filter_type", value="nearest" if tex.get("filter") == "nearest" else "bilinear")
        ET.SubElement(bitmap, "string", name="wrap_mode", value="repeat")

    def bsdf(self, parent, obj):
        b = obj["bsdf"]
        stem = names.file_stem(obj["name"])
        rough = b.get("roughness")
        is_rough = rough is not None and rough["alpha"] > 0
        if b["type"] == "diffuse" and b.get("fluorescence") is not None:
            node = ET.SubElement(parent, "bsdf", type="sb_fluorescent_diffuse")
            self.spectrum(node, "reflectance", b["reflectance"], f"{stem}_reflectance")
            rel = f"fluorescence/{stem}.txt"
            self.files.append(fluorescence.write_table(b["fluorescence"], self.out / rel))
            ET.SubElement(node, "string", name="reradiation", value=rel)
            self.plugins.add("sb_fluorescent_diffuse")
            return
        if b["type"] == "diffuse":
            node = ET.SubElement(parent, "bsdf", type="diffuse")
            self.reflectance(node, "reflectance", obj)
            return
        if b["type"] == "conductor" and b.get("thin_film") is not None:
            # this project's Python plugin (exporters/mitsuba_plugins/thin_film_conductor.py);
            # smooth or rough in one plugin: a distribution is written only when rough
            node = ET.SubElement(parent, "bsdf", type=THIN_FILM_PLUGIN)
            self.plugins.add(THIN_FILM_PLUGIN)
            film = b["thin_film"]
            for key, value in (("film_ior", film["ior"]), ("film_thickness", film["thickness"]),
                               ("ext_ior", film.get("ext_ior", 1.0))):
                ET.SubElement(node, "float", name=key, value=repr(float(value)))
            if "material" in b:
                ET.SubElement(node, "string", name="material", value=b["material"])
            else:
                self.spectrum(node, "eta", b["eta"], f"{stem}_eta")
                self.spectrum(node, "k", b["k"], f"{stem}_k")
        elif b["type"] == "conductor":
            node = ET.SubElement(parent, "bsdf", type="roughconductor" if is_rough else "conductor")
            if "material" in b:
                ET.SubElement(node, "string", name="material", value=b["material"])
            else:
                self.spectrum(node, "eta", b["eta"], f"{stem}_eta")
                self.spectrum(node, "k", b["k"], f"{stem}_k")
        elif b["type"] == "dielectric" and dispersion.is_dispersive(b["int_ior"]):
            # n(lambda): this project's plugin (Mitsuba 3's dielectrics take one IOR)
            self.plugins.add(DISPERSIVE_PLUGIN)
            node = ET.SubElement(parent, "bsdf", type=DISPERSIVE_PLUGIN)
            for key, value in dispersion.plugin_coefficients(b["int_ior"]).items():
                if isinstance(value, str):
                    ET.SubElement(node, "string", name=key, value=value)
                else:
                    ET.SubElement(node, "float", name=key, value=repr(float(value)))
            ET.SubElement(node, "float", name="ext_ior", value=repr(float(b.get("ext_ior", ir.AIR_IOR))))
        elif b["type"] == "dielectric":
            node = ET.SubElement(parent, "bsdf", type="roughdielectric" if is_rough else "dielectric")
            ET.SubElement(node, "float", name="int_ior", value=repr(float(b["int_ior"])))
            ET.SubElement(node, "float", name="ext_ior", value=repr(float(b.get("ext_ior", ir.AIR_IOR))))
        elif b["type"] == "coated_diffuse":
            # the IR's coated diffuse is Mitsuba 3's plastic / roughplastic with nonlinear false
            # (docs/scene-format.md 6.6); its spectral diffuse_reflectance is the base's albedo
            node = ET.SubElement(parent, "bsdf", type="roughplastic" if is_rough else "plastic")
            self.reflectance(node, "diffuse_reflectance", obj)
            ET.SubElement(node, "float", name="int_ior", value=repr(float(b["int_ior"])))
            ET.SubElement(node, "float", name="ext_ior", value=repr(float(b.get("ext_ior", ir.AIR_IOR))))
            ET.SubElement(node, "boolean", name="nonlinear", value="false")
        else:
            raise ValueError(f"unknown bsdf type {b['type']!r}")
        if is_rough:
            ET.SubElement(node, "string", name="distribution", value=rough["distribution"])
            ET.SubElement(node, "float", name="alpha", value=repr(float(rough["alpha"])))

    def shape(self, root, obj):
        s = obj["shape"]
        if s["type"] == "rectangle":
            node = ET.SubElement(root, "shape", type="rectangle", id=obj["name"])
            _transform(node, s["to_world"])
        elif s["type"] == "sphere":
            node = ET.SubElement(root, "shape", type="sphere", id=obj["name"])
            ET.SubElement(node, "point", name="center", x=repr(float(s["center"][0])),
                          y=repr(float(s["center"][1])), z=repr(float(s["center"][2])))
            ET.SubElement(node, "float", name="radius", value=repr(float(s["radius"])))
        elif s["type"] == "mesh":
            verts, faces = mesh_io.load_mesh(s, self.scene.get("_base_dir"))
            rel = f"meshes/{names.file_stem(obj['name'])}.ply"
            # Mitsuba's bitmap reads v down (row 0 at v = 0) and its PLY loader flips nothing: the
            # IR's v up is written as 1 - v (as its OBJ loader's flip_tex_coords does)
            uvs = None if s.get("uvs") is None else [[u, 1.0 - v] for u, v in s["uvs"]]
            self.files.append(mesh_io.write_ply(self.out / rel, verts, faces, uvs=uvs))
            node = ET.SubElement(root, "shape", type="ply", id=obj["name"])
            ET.SubElement(node, "string", name="filename", value=rel)
            # the IR's meshes carry no normals: their faces are flat (Mitsuba would otherwise
            # interpolate vertex normals it computes, which bends a prism's faces)
            ET.SubElement(node, "boolean", name="face_normals", value="true")
            if "to_world" in s:
                _transform(node, s["to_world"])
        else:
            raise ValueError(f"unknown shape type {s['type']!r}")
        if obj.get("bsdf"):
            self.bsdf(node, obj)
        elif obj.get("emitter"):
            # an emitter without a BSDF is black on reflection, as in the IR
            node_b = ET.SubElement(node, "bsdf", type="diffuse")
            ET.SubElement(node_b, "spectrum", name="reflectance", value="0")
        if obj.get("emitter") and obj["emitter"]["type"] == "collimated":
            # Mitsuba's directionalarea emits along the shape's normal; its "radiance" is the
            # irradiance across the beam (power per area: the ray weight is area x radiance)
            em = ET.SubElement(node, "emitter", type="directionalarea")
            self.spectrum(em, "radiance", obj["emitter"]["irradiance"], f"{names.file_stem(obj['name'])}_irradiance")
        elif obj.get("emitter"):
            em = ET.SubElement(node, "emitter", type="area")
            self.spectrum(em, "radiance", obj["emitter"]["radiance"], f"{names.file_stem(obj['name'])}_radiance")

    def light(self, root, light):
        """A delta light: Mitsuba's point, spot (its falloff is the IR's) and directional emitters."""
        stem = names.file_stem(light["name"])
        kind = light["type"]
        em = ET.SubElement(root, "emitter", type=kind, id=light["name"])
        if kind == "point":
            p = [repr(float(c)) for c in light["position"]]
            ET.SubElement(em, "point", name="position", x=p[0], y=p[1], z=p[2])
        elif kind == "spot":
            _transform(em, light["to_world"])
            ET.SubElement(em, "float", name="cutoff_angle", value=repr(float(light["cutoff_angle"])))
            ET.SubElement(em, "float", name="beam_width", value=repr(float(light["beam_width"])))
        else:
            d = [repr(float(c)) for c in light["direction"]]
            ET.SubElement(em, "vector", name="direction", x=d[0], y=d[1], z=d[2])
        key = "irradiance" if kind == "directional" else "intensity"
        self.spectrum(em, key, light[key], f"{stem}_{key}")

    def write(self):
        sc, r = self.scene, self.scene["render"]
        root = ET.Element("scene", version="3.0.0")
        root.append(ET.Comment(f" {names.comment_text(sc['name'])} ({names.comment_text(sc.get('case'))}), "
                               f"written from the scene IR v{ir.VERSION} "))
        ET.SubElement(root, "default", name="spp", value=str(r["spp"]))
        ET.SubElement(root, "default", name="seed", value="0")
        ET.SubElement(root, "default", name="max_depth", value=str(r.get("max_depth", 64)))
        parent = root
        cam = sc["camera"]
        polarizer = cam.get("polarizer")
        if r.get("output") == "stokes" or polarizer:
            # Mitsuba has no camera-side filter: the IR's ideal polariser is applied to the Stokes
            # vector after rendering (exporters/camera_filter.py)
            parent = ET.SubElement(root, "integrator", type="stokes")
        # path | ptracer; a fluorescent scene is traced by this project's bispectral path tracer
        integ = ET.SubElement(parent, "integrator",
                              type="sb_fluorescent_path" if self.fluorescent else r.get("integrator", "path"))
        if self.fluorescent:
            self.plugins.add("sb_fluorescent_path")
        ET.SubElement(integ, "integer", name="max_depth", value="$max_depth")
        sensor = ET.SubElement(root, "sensor", type="perspective")
        ET.SubElement(sensor, "float", name="fov", value=repr(float(cam["fov"])))
        ET.SubElement(sensor, "string", name="fov_axis", value=cam.get("fov_axis", "x"))
        _transform(sensor, np.asarray(cam["to_world"], dtype=np.float64) @ _CAMERA_FLIP)
        sampler = ET.SubElement(sensor, "sampler", type="independent")
        ET.SubElement(sampler, "integer", name="sample_count", value="$spp")
        ET.SubElement(sampler, "integer", name="seed", value="$seed")
        film = ET.SubElement(sensor, "film", type="hdrfilm")
        ET.SubElement(film, "integer", name="width", value=str(r["width"]))
        ET.SubElement(film, "integer", name="height", value=str(r["height"]))
        ET.SubElement(film, "string", name="pixel_format", value="rgb")
        # float32 when the film is written to a file (the mitsuba executable, load_plugins.py):
        # hdrfilm's default float16 rounds a constant region (a light seen directly: no variance)
        # by up to 2^-11, which the noise test sees at |z| in the thousands (measured)
        ET.SubElement(film, "string", name="component_format", value="float32")
        ET.SubElement(film, "rfilter", type="box")
        env = sc.get("environment")
        if textures.env_map(env):
            # linear sRGB radiance, uplifted by the spectral variants as an illuminant (D65 times
            # Jakob and Hanika's model); Mitsuba's map frame is y up with u = atan2(x, -z) / 2 pi, the
            # IR's (Blender's) z up with u = 1/2 - phi / 2 pi from +X: local x, y, z -> world y, z, x,
            # then the map's rotation about +Z (docs/scene-format.md 7.1)
            rel = textures.write_linear(env, "environment", sc.get("_base_dir"), self.out, stem="environment")
            self.files.append(self.out / rel)
            em = ET.SubElement(root, "emitter", type="envmap", id="environment")
            ET.SubElement(em, "string", name="filename", value=rel)
            ET.SubElement(em, "float", name="scale", value=repr(float(env.get("scale", 1.0))))
            a = np.radians(float(env.get("rotation", 0.0)))
            rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
            m = np.eye(4)
            m[:3, :3] = rz @ np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=np.float64)
            _transform(em, m.tolist())
        elif env:
            em = ET.SubElement(root, "emitter", type="constant", id="environment")
            self.spectrum(em, "radiance", env["radiance"], "environment_radiance")
        for obj in sc["objects"]:
            self.shape(root, obj)
        for light in sc.get("lights", []):
            self.light(root, light)
        if polarizer:
            root.insert(1, ET.Comment(
                f" renders S0..S3; the camera's ideal linear polariser at {float(polarizer['angle'])!r} deg "
                f"(counter-clockwise from image right, S1 > 0 horizontal) is applied afterwards: I = (S0 + S1 cos 2t "
                f"+ S2 sin 2t) / 2, as {camera_filter.POSTPROCESS} says "))
        if self.plugins:
            root.insert(1, ET.Comment(f" needs Python plugins {', '.join(sorted(self.plugins))}: see load_plugins.py "))
        ET.indent(root, space="  ")
        self.out.mkdir(parents=True, exist_ok=True)
        if self.plugins:
            mitsuba_plugins.write_into(self.out, self.plugins)
        if polarizer:
            camera_filter.write(self.out, polarizer["angle"], keep_stokes=r.get("output") == "stokes")
        xml_path = self.out / "scene.xml"
        ET.ElementTree(root).write(xml_path, encoding="utf-8", xml_declaration=True)
        return xml_path


def write(scene, out_dir):
    """Write ``scene`` into ``out_dir``; returns the path of scene.xml."""
    return _Writer(scene, out_dir).write()
