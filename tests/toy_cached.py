#!/usr/bin/env python3
"""The example renderer (examples/your_renderer/toy_renderer.py) with its renders kept in the
test render cache (tests/render_cache.py): the same command line, the same output; a renderer
declared with it renders a scene, samples and seed once per cache, however many of its planted
variants (``--gain``, ``--band-swap``: applied to the output) ask for it. The tests that declare
it (tests/verdict/test_bands.py) take every other word of the declaration from the example's own
TOML files.

    python tests/toy_cached.py scene.xml --out pass.exr --spp 64 --seed 0 [--format spectral] ...
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "examples" / "your_renderer"))
import render_cache  # noqa: E402
import toy_renderer  # noqa: E402

_render_rgb, _render_bands = toy_renderer.render_rgb, toy_renderer.render_bands
toy_renderer.render_rgb = lambda xml, spp, seed: render_cache.memo(lambda: _render_rgb(xml, spp, seed), xml, "rgb", spp, seed)
toy_renderer.render_bands = lambda xml, spp, seed: render_cache.memo(lambda: _render_bands(xml, spp, seed), xml, "bands", spp, seed)

if __name__ == "__main__":
    sys.exit(toy_renderer.main())
