"""The writers' planted-error test hooks: a factor read from an environment variable.

A writer's test hook (docs/developing.md, "Test hooks") multiplies what it writes for every light
by the factor the variable holds, so that a test can plant an error the renders must detect
(``SPECTRAL_BENCH_TEST_ART_ILLUMINANT_SCALE``: art_writer; ``SPECTRAL_BENCH_TEST_PBRT_LIGHT_SCALE``:
pbrt_writer). Unset or empty, nothing changes.
"""
import math
import os


def scale(variable):
    """The factor the environment variable ``variable`` holds (1.0 when unset or empty); a value
    that is not a positive finite number is a ValueError naming the variable."""
    text = os.environ.get(variable)
    if not text:
        return 1.0
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"{variable}={text!r}: expected a positive number (a test hook's planted factor)")
    return value
