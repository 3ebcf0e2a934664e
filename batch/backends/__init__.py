"""Renderer backends. Each one exports an IR scene to its format, picks the cheapest mode that
models what the scene needs (or says plainly that it cannot), and renders to EXR."""
from .mitsuba_backend import MitsubaBackend

BACKENDS = {"mitsuba": MitsubaBackend}


def get(name, **options):
    if name not in BACKENDS:
        raise KeyError(f"unknown backend {name!r} (known: {', '.join(BACKENDS)})")
    return BACKENDS[name](**options)
