"""The self-contained form of a scene file: every named thing carries its data.

A scene names data that lives in the project (``exporters/data/*.json``, ``dispersion.py``):
illuminants and ColorChecker reflectances (``{"type": "named", "name": "cie_d65"}``),
conductors (``"material": "Cu"``) and glasses (``int_ior: {"type": "named", "name": "N-BK7"}``).
A scene file written by ``ir_json.write`` carries that data beside the name (``embed``), so that
a renderer outside the project can import it (docs/scene-format.md):

- a named spectrum gains ``wavelengths`` (nm) and ``values``: its value is
  ``scale * values`` linearly interpolated, edge values beyond the table. Illuminant tables are
  stored already normalised to 1.0 at 560 nm (the IR's radiometric convention, spectra.py);
  reflectances as measured. So the one rule ``scale * interp(values)`` holds for every name.
- a named conductor gains ``eta`` and ``k`` (sampled spectra, absolute indices).
- a named glass gains ``model: "sellmeier"`` and its coefficients ``B`` and ``C`` (um^2).

Inside the project the IR keeps the named form (the writers use names: Mitsuba's own conductor
tables, ART's own illuminants; references fingerprint the named form). ``apply`` turns a file's
inline data back into the internal IR, and it decides what a disagreement means:

    The inline data wins; the name is only a label.

- inline data equal to the project's table (to ``RTOL``, i.e. the same table as printed with
  9 significant digits) is dropped: the scene is the named one, and renders, exports and
  fingerprints exactly as the named one does;
- inline data that differs (a user edited it, or the project's table changed since the file
  was written) replaces the name: the spectrum becomes ``sampled`` (values times scale), the
  conductor an explicit ``eta``/``k`` conductor, the glass a ``sellmeier`` model. The scene is
  what its file says, and a reference rendered from the named scene is stale for it (its
  fingerprint differs);
- inline data under a name the project does not know is used the same way (a file written by a
  later version, or by another tool, stays importable).

``apply`` runs before validation, on data that may be malformed: it changes only what has
the exact shape of inline data (lists of numbers of equal length) and leaves anything else to
the schema, which names the field.
"""
import copy
import math

from . import dispersion, spectra

DIGITS = 12  # significant digits of a normalised table (the CIE data have 6; no float noise in files)
RTOL = 1e-9  # inline values within this relative difference of the project's are the project's


# -- writing: the named IR -> the self-contained form ------------------------------------------
def named_spectrum_table(name):
    """(wavelengths, values) of a named spectrum as the self-contained form stores it: the
    project's table, illuminants divided by their value at 560 nm (to DIGITS significant digits)."""
    table, normalised = spectra._named_tables()[name]
    wl = [float(w) for w in table["wavelengths"]]
    ref = float(spectra._interp_padded(spectra.NORMALISATION_NM, wl, table["values"])) if normalised else 1.0
    return wl, [float(f"{float(v) / ref:.{DIGITS}g}") for v in table["values"]]


def _embed_spectrum(spec):
    if isinstance(spec, dict) and spec.get("type") == "named" and spec.get("name") in spectra.named_spectra() \
            and "values" not in spec:
        spec["wavelengths"], spec["values"] = named_spectrum_table(spec["name"])


def _embed(node):
    if isinstance(node, dict):
        if node.get("type") == "conductor" and node.get("material") in spectra.NAMED_CONDUCTORS \
                and "eta" not in node and "k" not in node:
            node["eta"], node["k"] = copy.deepcopy(spectra.named_conductor(node["material"]))
        if node.get("type") == "dielectric" and isinstance(node.get("int_ior"), dict):
            ior = node["int_ior"]
            if ior.get("type") == "named" and ior.get("name") in dispersion.NAMED_GLASSES and "B" not in ior:
                glass = dispersion.NAMED_GLASSES[ior["name"]]
                ior.update(model="sellmeier", B=[float(x) for x in glass["B"]], C=[float(x) for x in glass["C"]])
        else:
            _embed_spectrum(node)
        for v in node.values():
            _embed(v)
    elif isinstance(node, list):
        for v in node:
            _embed(v)
    return node


def embed(scene):
    """A copy of ``scene`` in the self-contained form (the scene itself is not changed)."""
    return _embed(copy.deepcopy({k: v for k, v in scene.items() if not k.startswith("_")}))


# -- reading: the self-contained form -> the internal IR -----------------------------------------
def _numbers(x):
    return isinstance(x, list) and len(x) > 0 and all(
        isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in x)


def _same(a, b):
    return len(a) == len(b) and all(math.isclose(x, y, rel_tol=RTOL, abs_tol=1e-300) for x, y in zip(a, b))


def _apply_spectrum(spec):
    """The internal form of one spectrum dict (in place); anything not shaped as inline data
    is left for the schema to name."""
    if not (isinstance(spec, dict) and spec.get("type") == "named" and ("wavelengths" in spec or "values" in spec)):
        return
    wl, values = spec.get("wavelengths"), spec.get("values")
    if not (_numbers(wl) and _numbers(values) and len(wl) == len(values)):
        return
    name = spec.get("name")
    if isinstance(name, str) and name in spectra.named_spectra():
        own_wl, own_values = named_spectrum_table(name)
        if _same(wl, own_wl) and _same(values, own_values):
            del spec["wavelengths"], spec["values"]
            return
    scale = spec.get("scale", 1.0)
    if not (isinstance(scale, (int, float)) and not isinstance(scale, bool)):
        return  # the schema names the scale
    spec.clear()
    spec.update(type="sampled", wavelengths=wl, values=[scale * v for v in values])


def _sampled(spec):
    return (isinstance(spec, dict) and spec.get("type") == "sampled" and _numbers(spec.get("wavelengths"))
            and _numbers(spec.get("values")) and len(spec["wavelengths"]) == len(spec["values"]))


def _apply_conductor(bsdf):
    if "material" not in bsdf or not ("eta" in bsdf and "k" in bsdf):
        return
    if bsdf["material"] in spectra.NAMED_CONDUCTORS and _sampled(bsdf["eta"]) and _sampled(bsdf["k"]):
        eta, k = spectra.named_conductor(bsdf["material"])
        if all(_same(mine[key], own[key]) for mine, own in ((bsdf["eta"], eta), (bsdf["k"], k))
               for key in ("wavelengths", "values")):
            del bsdf["eta"], bsdf["k"]
            return
    del bsdf["material"]  # eta and k win; the schema and validation check them


def _apply_glass(ior):
    if not (isinstance(ior, dict) and ior.get("type") == "named" and ("B" in ior or "C" in ior)):
        return
    b, c = ior.get("B"), ior.get("C")
    if ior.get("model", "sellmeier") != "sellmeier" or not (_numbers(b) and _numbers(c)):
        return
    own = dispersion.NAMED_GLASSES.get(ior.get("name")) if isinstance(ior.get("name"), str) else None
    if own is not None and _same(b, own["B"]) and _same(c, own["C"]):
        for key in ("model", "B", "C"):
            ior.pop(key, None)
        return
    ior.clear()
    ior.update(type="sellmeier", B=b, C=c)


def _apply(node):
    if isinstance(node, dict):
        if node.get("type") == "conductor":
            _apply_conductor(node)
        elif node.get("type") == "dielectric":
            _apply_glass(node.get("int_ior"))
        else:
            _apply_spectrum(node)
        for v in list(node.values()):
            _apply(v)
    elif isinstance(node, list):
        for v in node:
            _apply(v)
    return node


def apply(scene):
    """Turn a scene file's inline data into the internal IR, in place (see the module docstring:
    data equal to the project's is dropped, data that differs replaces the name)."""
    return _apply(scene)
