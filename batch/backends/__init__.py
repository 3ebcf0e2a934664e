"""Renderer backends. Each one exports an IR scene to its format, picks the cheapest mode that
models what the scene needs (or says plainly that it cannot), and renders to EXR."""
from .art_backend import ArtBackend
from .mitsuba_backend import BackendFailure, MitsubaBackend  # noqa: F401 - BackendFailure is part of the interface

BACKENDS = {"mitsuba": MitsubaBackend, "art": ArtBackend}


def get(name, **options):
    if name not in BACKENDS:
        raise KeyError(f"unknown backend {name!r} (known: {', '.join(BACKENDS)})")
    return BACKENDS[name](**options)
