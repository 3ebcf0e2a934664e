"""Run Blender panels' draw code headless: a stand-in for bpy.types.UILayout that records every
call and checks it against Blender's own RNA, so that a panel drawing a property, operator,
operator property, icon or keyword argument that does not exist fails here instead of showing a
user a traceback.

Panel.draw() cannot run in the bpy module with a real layout (no window), but it is a plain
function of (self, context): it is called with a stand-in ``self`` holding this layout and a
context stand-in holding real bpy data. Used by tests/extension/test_blender_ui.py and
tests/extension/test_extension.py (inside a child process with bpy).
"""
import bpy

UI = bpy.types.UILayout.bl_rna


class DrawError(AssertionError):
    pass


def _check_value(prop, value, what):
    """Check ``value`` against an RNA property or parameter definition."""
    kind = prop.type
    if kind == "ENUM":
        items = prop.enum_items.keys()
        values = value if isinstance(value, (set, frozenset)) else {value}
        if items and not all(v in items for v in values):  # dynamic enums list no items here
            raise DrawError(f"{what}: {value!r} is not one of {sorted(items)[:12]}...")
    elif kind == "STRING" and not isinstance(value, str):
        raise DrawError(f"{what}: expects a string, got {value!r}")
    elif kind == "BOOLEAN" and not isinstance(value, bool):
        raise DrawError(f"{what}: expects a bool, got {value!r}")
    elif kind in ("INT", "FLOAT") and getattr(prop, "array_length", 0) == 0 and not isinstance(value, (int, float)):
        raise DrawError(f"{what}: expects a number, got {value!r}")


def _check_call(func, args, kwargs, where):
    params = UI.functions[func].parameters
    names = list(params.keys())
    if len(args) > len(names):
        raise DrawError(f"{where}: UILayout.{func}() takes {len(names)} arguments, got {len(args)}")
    bound = dict(zip(names, args))
    for key, value in kwargs.items():
        if key not in params:
            raise DrawError(f"{where}: UILayout.{func}() has no argument {key!r} (has {names})")
        if key in bound:
            raise DrawError(f"{where}: UILayout.{func}() got {key!r} twice")
        bound[key] = value
    for key, value in bound.items():
        if params[key].type != "POINTER" and value is not None:
            _check_value(params[key], value, f"{where}: UILayout.{func}({key}=...)")
    return bound


def _rna_property(data, name, where):
    rna = getattr(data, "bl_rna", None)
    if rna is None:
        raise DrawError(f"{where}: {data!r} is not RNA data (no bl_rna)")
    if name not in rna.properties:
        raise DrawError(f"{where}: {rna.identifier} has no property {name!r}")
    return rna.properties[name]


class OperatorProperties:
    """What layout.operator() returns: setting a property the operator does not have fails."""

    def __init__(self, idname, rna, where, record):
        object.__setattr__(self, "_idname", idname)
        object.__setattr__(self, "_rna", rna)
        object.__setattr__(self, "_where", where)
        object.__setattr__(self, "_record", record)

    def __setattr__(self, name, value):
        rna = object.__getattribute__(self, "_rna")
        where = f"{object.__getattribute__(self, '_where')}: operator {object.__getattribute__(self, '_idname')}"
        if name not in rna.properties:
            raise DrawError(f"{where} has no property {name!r}")
        _check_value(rna.properties[name], value, f"{where}.{name}")
        object.__getattribute__(self, "_record")[name] = value

    def __getattr__(self, name):
        raise DrawError(f"{object.__getattribute__(self, '_where')}: reading operator properties while drawing ({name})")


def operator_rna(idname, where):
    module, _, name = idname.partition(".")
    try:
        return getattr(getattr(bpy.ops, module), name).get_rna_type()
    except (AttributeError, KeyError) as exc:
        raise DrawError(f"{where}: no registered operator {idname!r}") from exc


class Layout:
    """Records calls as (path, function, arguments) into ``calls``; returns child layouts."""

    def __init__(self, calls, where):
        object.__setattr__(self, "_calls", calls)
        object.__setattr__(self, "_where", where)

    def __setattr__(self, name, value):
        where = object.__getattribute__(self, "_where")
        if name not in UI.properties:
            raise DrawError(f"{where}: UILayout has no attribute {name!r}")
        _check_value(UI.properties[name], value, f"{where}: UILayout.{name}")
        object.__getattribute__(self, "_calls").append((where, f"set {name}", {"value": value}))

    def __getattr__(self, name):
        where = object.__getattribute__(self, "_where")
        if name in UI.functions:
            raise DrawError(f"{where}: the layout stand-in does not implement UILayout.{name}() yet: add it "
                            "to tests/layout_recorder.py")
        if name in UI.properties:
            return None
        raise DrawError(f"{where}: UILayout has no attribute {name!r}")

    def _log(self, func, args):
        object.__getattribute__(self, "_calls").append((object.__getattribute__(self, "_where"), func, args))

    def _child(self, func, args, kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call(func, args, kwargs, where)
        self._log(func, bound)
        return Layout(object.__getattribute__(self, "_calls"), f"{where}/{func}")

    # containers
    def row(self, *args, **kwargs):
        return self._child("row", args, kwargs)

    def column(self, *args, **kwargs):
        return self._child("column", args, kwargs)

    def box(self, *args, **kwargs):
        return self._child("box", args, kwargs)

    def split(self, *args, **kwargs):
        return self._child("split", args, kwargs)

    def grid_flow(self, *args, **kwargs):
        return self._child("grid_flow", args, kwargs)

    def column_flow(self, *args, **kwargs):
        return self._child("column_flow", args, kwargs)

    # items
    def label(self, *args, **kwargs):
        self._log("label", _check_call("label", args, kwargs, object.__getattribute__(self, "_where")))

    def separator(self, *args, **kwargs):
        self._log("separator", _check_call("separator", args, kwargs, object.__getattribute__(self, "_where")))

    def progress(self, *args, **kwargs):
        self._log("progress", _check_call("progress", args, kwargs, object.__getattribute__(self, "_where")))

    def prop(self, *args, **kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call("prop", args, kwargs, where)
        _rna_property(bound["data"], bound["property"], where)
        self._log("prop", {k: v for k, v in bound.items() if k != "data"})

    def prop_search(self, *args, **kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call("prop_search", args, kwargs, where)
        _rna_property(bound["data"], bound["property"], where)
        _rna_property(bound["search_data"], bound["search_property"], where)
        self._log("prop_search", {"property": bound["property"]})

    def template_list(self, *args, **kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call("template_list", args, kwargs, where)
        if not hasattr(bpy.types, bound["listtype_name"]):
            raise DrawError(f"{where}: no registered UIList {bound['listtype_name']!r}")
        _rna_property(bound["dataptr"], bound["propname"], where)
        _rna_property(bound["active_dataptr"], bound["active_propname"], where)
        self._log("template_list", {"propname": bound["propname"]})

    def operator(self, *args, **kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call("operator", args, kwargs, where)
        rna = operator_rna(bound["operator"], where)
        record = {}
        self._log("operator", dict(bound, properties=record))
        return OperatorProperties(bound["operator"], rna, where, record)

    def menu(self, *args, **kwargs):
        where = object.__getattribute__(self, "_where")
        bound = _check_call("menu", args, kwargs, where)
        if not hasattr(bpy.types, bound["menu"]):
            raise DrawError(f"{where}: no registered menu {bound['menu']!r}")
        self._log("menu", bound)


class Drawn:
    """Stands in for the Panel (or AddonPreferences, or Menu) instance: ``layout`` is the recorder,
    every other attribute is read from ``instance`` (the real preferences) or the class."""

    def __init__(self, cls, layout, instance=None):
        object.__setattr__(self, "_cls", cls)
        object.__setattr__(self, "_instance", instance)
        object.__setattr__(self, "layout", layout)

    def __getattr__(self, name):
        instance = object.__getattribute__(self, "_instance")
        return getattr(instance if instance is not None else object.__getattribute__(self, "_cls"), name)


class Context:
    """A context stand-in for the Properties editor: real bpy data, no window."""

    def __init__(self, **data):
        self.window_manager = bpy.context.window_manager
        self.preferences = bpy.context.preferences
        self.screen = self.window = self.area = self.region = self.space_data = None
        self.scene = data.pop("scene", bpy.context.scene)
        self.object = data.pop("object", None)
        self.material = data.pop("material", None)
        self.world = data.pop("world", self.scene.world if self.scene else None)
        self.light = self.object.data if self.object is not None and self.object.type == "LIGHT" else None
        self.camera = self.object.data if self.object is not None and self.object.type == "CAMERA" else None
        for key, value in data.items():
            setattr(self, key, value)


def draw(cls, context, instance=None):
    """Call ``cls``'s poll() and, if it passes, draw_header() and draw() with a recording layout;
    returns the recorded calls, or None when poll() said no."""
    poll = getattr(cls, "poll", None)
    if poll is not None and not poll(context):
        return None
    calls = []
    drawn = Drawn(cls, Layout(calls, cls.__name__), instance)
    if hasattr(cls, "draw_header"):
        cls.draw_header(drawn, context)
    cls.draw(drawn, context)
    return calls


def draw_function(func, context, name):
    """Draw a menu-append function ``func(self, context)`` (e.g. the File > Export entries)."""
    calls = []
    func(Drawn(object, Layout(calls, name)), context)
    return calls


def registered_panels(package):
    """Every registered Panel class defined in ``package`` (the extension's Python package)."""
    def walk(cls):
        for sub in cls.__subclasses__():
            yield sub
            yield from walk(sub)
    return sorted({c for c in walk(bpy.types.Panel) if c.__module__.startswith(package + ".")
                   and getattr(c, "is_registered", False)}, key=lambda c: c.__name__)
