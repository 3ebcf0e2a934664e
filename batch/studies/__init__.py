"""Studies made of more renders: speed against accuracy (sweeps) and stability strips."""
