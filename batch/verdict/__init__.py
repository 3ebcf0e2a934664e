"""Verdicts: comparison with references on noise, analytic probes (ground truth from no renderer), FLIP."""
