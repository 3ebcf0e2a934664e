"""The scene format is specified: every property of the JSON Schema has a description, and
docs/scene-format.md states the schema's version and names every property."""
import copy
import json
import re

from conftest import ROOT
from spectral_bench.exporters import ir, validate

DOC = ROOT / "docs" / "scene-format.md"
COMBINATORS = ("oneOf", "anyOf", "allOf", "not", "if", "then", "else", "items", "prefixItems", "contains",
               "additionalProperties", "dependentSchemas", "patternProperties")


def properties(schema, path="#"):
    """(JSON pointer, property name, subschema) of every property anywhere in ``schema``: under
    properties, $defs/definitions, items and every combinator's branches, recursively."""
    if isinstance(schema, list):
        for i, s in enumerate(schema):
            yield from properties(s, f"{path}/{i}")
        return
    if not isinstance(schema, dict):
        return
    for name, sub in schema.get("properties", {}).items():
        yield f"{path}/properties/{name}", name, sub
        yield from properties(sub, f"{path}/properties/{name}")
    for key in ("$defs", "definitions", "patternProperties", "dependentSchemas"):
        for name, sub in schema.get(key, {}).items():
            yield from properties(sub, f"{path}/{key}/{name}")
    for key in COMBINATORS:
        if key in schema and key not in ("patternProperties", "dependentSchemas"):
            yield from properties(schema[key], f"{path}/{key}")


def undescribed(schema):
    """Pointers of properties (and of $defs entries) without a non-empty description."""
    missing = [p for p, _, sub in properties(schema)
               if not (isinstance(sub, dict) and isinstance(sub.get("description"), str) and sub["description"].strip())]
    missing += [f"#/$defs/{name}" for name, sub in schema.get("$defs", {}).items() if not sub.get("description")]
    return missing


def test_every_schema_property_has_a_description():
    schema = validate.schema()
    assert len(list(properties(schema))) > 90  # the walk reaches the branches, not just the top level
    assert undescribed(schema) == []


def test_the_walk_names_a_property_without_a_description_wherever_it_is():
    schema = validate.schema()
    for pointer in ("#/properties/render/properties/spp", "#/$defs/spectrum/oneOf/2/properties/values",
                    "#/$defs/object/properties/emitter/oneOf/2/properties/irradiance",
                    "#/$defs/fluorescence/oneOf/0/properties/strength"):
        broken = copy.deepcopy(schema)
        node = broken
        for part in pointer[2:].split("/"):
            node = node[int(part)] if isinstance(node, list) else node[part]
        del node["description"]
        assert undescribed(broken) == [pointer]


def test_the_specification_states_the_schema_version():
    text = DOC.read_text()
    schema = validate.schema()
    assert schema["properties"]["version"]["const"] == ir.VERSION
    assert f"# The scene format ({ir.FORMAT}, version {ir.VERSION})" in text.splitlines()[0]
    assert schema["$id"] in text
    assert "docs/scene-format.md" in schema["description"]


def test_the_specification_names_every_property():
    """Every property name of the schema appears in docs/scene-format.md as `name` (or inside a
    quoted JSON example), so the document covers the whole format."""
    text = DOC.read_text()
    named = set(re.findall(r"`([A-Za-z_][A-Za-z0-9_]*)`", text)) | set(re.findall(r'"([A-Za-z_][A-Za-z0-9_]*)"', text))
    missing = sorted({name for _, name, _ in properties(validate.schema())} - named)
    assert missing == []


def test_the_specification_states_the_conventions_an_importer_needs():
    """The conventions issue 22 lists, each where an importer looks for it."""
    text = " ".join(DOC.read_text().split())
    for phrase in ("full** angle", "`fov_axis`: `\"x\"` (the default", "pinhole", "pixel (0, 0) is the **top-left**",
                   "default **1.000277**", "default **1.0**", "front side only", "**+Z normal**",
                   "**default 64**", "linear sRGB", "CIE 1931 2-degree", "**1 nm**", "360-830 nm",
                   "**flat spectrum 1 has Y = 1**", "**s at 560 nm**", "linearly interpolated",
                   "**edge values**", "`stderr.<channel>`", "`S0.R`", "**S1 > 0 is horizontal**",
                   "One-sided", "**two-sided**", "row-major", "**+Z up**"):
        assert phrase in text, phrase
    json.loads(json.dumps(validate.schema()))  # the schema stays plain JSON
