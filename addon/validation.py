"""Inline validation of annotations for the panels: the IR's own checks, as messages.

A panel shows these under the fields instead of letting an export raise later."""
from ..exporters import extract_blender, spectra, validate


def material_problems(mat):
    a = mat.spectral_bench
    if a.kind == "NONE":
        return ["Not annotated: exported from its shader nodes (Principled BSDF, ...), each conversion a warning; "
                "set a Model to give its spectra"]
    if a.kind == "CONDUCTOR" and a.conductor_named and a.conductor not in spectra.NAMED_CONDUCTORS:
        return [f"Unknown conductor {a.conductor!r}"]
    if a.kind == "DIFFUSE":
        try:
            extract_blender.fluorescence(a)
        except ValueError as exc:
            return [f"fluorescence_matrix_file: {exc}"]
    bsdf = extract_blender.material_bsdf(mat)
    return [f"{field}: {msg}" for field, msg in validate.bsdf_problems(bsdf)]


def spectrum_problems(props, label):
    return [f"{label}.{field}: {msg}" for field, msg in spectra.check(extract_blender.spectrum(props), label)]


def light_problems(light):
    if not extract_blender.light_annotated(light):
        return ["Not annotated: exported from its power and colour (docs/scene-format.md section 11)"]
    if light.spectral_bench.collimated and (light.type != "AREA" or light.shape not in ("SQUARE", "RECTANGLE")):
        return ["A collimated beam needs a square or rectangular area light"]
    return spectrum_problems(light.spectral_bench.radiance, "radiance")


def world_problems(world):
    a = world.spectral_bench
    return spectrum_problems(a.radiance, "radiance") if a.enabled else []
