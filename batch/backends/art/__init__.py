"""ART (the Advanced Rendering Toolkit): the backend that runs `artist` on exported .arm scenes."""
