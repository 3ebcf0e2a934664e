"""Reference code: the appearance models of spectral_bench scenes as a standalone numpy module
(appearance.py; its C++17 translation is snippets/). See docs/scene-format.md."""
