"""The extension's preferences (Edit > Preferences > Add-ons > Spectral Render Benchmark), saved
with Blender's own preferences: where references come from, and the renderers files that declare
the user's own renderers (docs/backends.md, "Add your renderer"; batch/backends/command.py reads them).

References ship inside the extension (references/ beside scenes.blend). A folder of the user's
own (a checkout's references/, a re-rendered set, references for the user's own scenes) can be
added or used instead; for each scene the first folder holding a reference usable for it wins,
and every result names the reference it was judged against.
"""
from pathlib import Path

import bpy
from bpy.props import CollectionProperty, EnumProperty, StringProperty

from . import reference_sources

# the extension's package: "bl_ext.<repository>.spectral_bench" when installed, "spectral_bench"
# when the repository is imported directly (tests, batch): preferences exist only in the former
ROOT_PACKAGE = __package__.rpartition(".")[0]

SOURCES = [
    ("BOTH", "Folder, Then Extension", "The folder's reference where it has a usable one, else the extension's"),
    ("FOLDER", "Folder Only", "Only the references in the chosen folder"),
    ("EXTENSION", "Extension Only", "Only the references shipped with the extension"),
]


class RenderersFile(bpy.types.PropertyGroup):
    """One renderers file: a TOML file of [renderers.NAME] tables, passed to a run as --renderers."""
    path: StringProperty(name="Renderers File", subtype="FILE_PATH", default="",
                         description="A TOML file declaring renderers that run as a command "
                                     "([renderers.NAME] tables; docs/backends.md, Add your renderer)")


class SpectralBenchPreferences(bpy.types.AddonPreferences):
    bl_idname = ROOT_PACKAGE

    references_dir: StringProperty(
        name="References Folder", subtype="DIR_PATH", default="",
        description="A folder of reference EXRs with their .json provenance (e.g. a checkout's references/, "
                    "or references rendered with batch/make_references.py --out FOLDER)")
    reference_source: EnumProperty(name="Use", items=SOURCES, default="BOTH",
                                   description="Which references judge a render")
    renderers_files: CollectionProperty(type=RenderersFile, name="Renderers Files")

    def draw(self, context):
        layout = self.layout
        draw_renderers_files(layout, self)
        layout.prop(self, "references_dir")
        layout.prop(self, "reference_source")
        search = reference_folders(context, self)
        if not search:
            layout.label(text="No reference folder: choose one, or use the extension's references", icon="ERROR")
        for origin, folder, count, exists in reference_sources.summary(search):
            text = f"{origin}: {count} references in {folder}" if exists else f"{origin}: no such folder {folder}"
            layout.label(text=text, icon="CHECKMARK" if count else "ERROR")


def draw_renderers_files(layout, prefs):
    """The renderers files, each with its remove button, and the button that adds one."""
    col = layout.column(align=True)
    col.label(text="Renderers Files (your own renderers, declared in TOML)")
    for i, item in enumerate(prefs.renderers_files):
        row = col.row(align=True)
        row.prop(item, "path", text="")
        row.operator("spectral_bench.remove_renderers_file", text="", icon="REMOVE").index = i
    col.operator("spectral_bench.add_renderers_file", text="Add Renderers File", icon="ADD")


class Defaults:
    """The preferences' values where the extension is not enabled as an extension (tests, scripts
    that import the repository): the shipped references only, no renderers files."""
    references_dir = ""
    reference_source = "BOTH"
    renderers_files = ()


def settings(context=None):
    """The extension's preferences, or their defaults when they do not exist."""
    prefs = (context or bpy.context).preferences
    addon = prefs.addons.get(ROOT_PACKAGE)
    return addon.preferences if addon is not None and addon.preferences is not None else Defaults()


def reference_folders(context=None, prefs=None):
    """[(origin, Path)] to search, in order ("folder": the preferences' folder; "extension": shipped)."""
    prefs = prefs or settings(context)
    user = Path(bpy.path.abspath(prefs.references_dir)) if prefs.references_dir else None
    return reference_sources.folders(prefs.reference_source, user)


def renderers_files(context=None, prefs=None):
    """[Path] of the renderers files, absolute (a run passes each as --renderers), in the order
    given, without blanks or repeats."""
    prefs = prefs or settings(context)
    out = []
    for item in prefs.renderers_files:
        if item.path.strip():
            path = Path(bpy.path.abspath(item.path)).resolve()
            if path not in out:
                out.append(path)
    return out


CLASSES = (RenderersFile, SpectralBenchPreferences)


register, unregister = bpy.utils.register_classes_factory(CLASSES)
