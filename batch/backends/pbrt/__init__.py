"""pbrt-v4: the backend that runs `pbrt` on exported .pbrt scenes through its spectral film."""
