"""Statistics as text: z scores and p-values printed the same way wherever they are printed (the
reasons, summary.md, the report, the diagnosis), readable whatever their size (issue 40: a
standard error next to zero made a z of 300 digits)."""
import math


def format_z(z, decimals=None):
    """A z score as text: 3 significant digits whatever its size (``-6.27``, ``412``,
    ``1.23e+03``, ``-6.3e+299``: never hundreds of digits), or ``decimals`` fixed decimals where
    that is shorter than 7 characters before the point (the noise test's ``z_max 1.20``). ``n/a``
    for None or NaN."""
    if z is None or math.isnan(z):
        return "n/a"
    z = float(z)
    if decimals is not None and abs(z) < 1e4:
        return f"{z:.{decimals}f}"
    return f"{z:.3g}"


def format_p(p):
    """A p-value as text: 3 significant digits (``0.524``, ``0.00167``, ``3.1e-12``), ``< 1e-300``
    below what a double holds beside 0 (a p of exactly 0 is an underflow, not a certainty). ``n/a``
    for None or NaN."""
    if p is None or not math.isfinite(p):
        return "n/a"
    p = float(p)
    if p < 1e-300:
        return "< 1e-300"
    return f"{p:.3g}"
