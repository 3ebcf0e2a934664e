"""LuxCoreRender (an RGB renderer): the backend and its worker process (pyluxcore)."""
