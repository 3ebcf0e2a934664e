"""Diagnosis: error models fitted to a failing render, naming the likely cause with its size and how
much of the difference it explains (issue 34). Advice only: it never changes a status.

The catalogue is data, one module per family (a registry like the probes'):

- image.py: uniform scale, per-channel scale, additive offset, sRGB transfer applied or missing,
  gamma, colour-space mix-ups and channel order, flips and transpose, sub-pixel/one-pixel shift,
  zoom, clamped highlights;
- polarisation.py: Stokes frame rotated, S3 sign, depolarised output, polariser angle;
- spectral.py: the film's observer (CIE 1964, Mitsuba's 5 nm table), a wavelength shift,
  the illuminant normalised (to Y = 1, at 560 nm, to its peak);
- materials.py: GGX alpha fitted (alpha vs alpha squared noted), Beckmann for GGX, conductor
  without its k, the dielectric's IOR, emitter units (x pi);
- noise.py: the standard error under- or over-reported.

- materials.py also: fluorescence dropped (the lone fluorescent sphere's probe without the
  re-radiated light), thin film missing and its thickness fitted (the Airy probe's tiles).

- materials.py also: dispersion missing (the prism's band positions as one IOR puts them).
- materials.py also: multiple scattering (the GGX white furnace's missing energy 1 - E, a share of it
  kept: Kulla and Conty 2017) and the height-correlated Smith form there.
- noise.py also: too few samples (a render of one pass noisier than its declared spp gives).

Not in the catalogue (issue 34 lists it): per-steradian vs per-area beyond the factor pi (it is
that factor: "emitter radiance x pi").

Each model is a Model: its name, family, the parameters it fits, the evidence it uses
("reference": the render's blocks against the reference's, the noise test's own blocks and
variances; or "probe:<kind>": the render against a probe's closed-form truth) and a one-line
explanation. Its ``fit(evidence)`` returns a Fit or None (the model does not apply here).

Fitting: weighted least squares on the evidence's blocks (or probe regions). On the reference
evidence the weights are the scale test's (the block variance the reference predicts: weights
that cannot correlate with the render's noise, so they cannot bias the fit), and the standard
errors the cluster-robust sandwich on the residuals (CR1, a block's colour channels one cluster:
``least_squares``). Measured on real renders: with the noise test's block variances as known
weights and (J^T J)^-1, a uniform scale's standard error came out 1.6 times too small (R, G and B
of a path tracer are nearly one measurement, counted as three) and the GGX alpha fits of three
seeds spread twice as wide as their standard errors; the sandwich gives 0.00047 for the scale
(seeds: 0.9993, 1.0005, 0.9993 on a correct render) and 0.00013-0.00024 for alpha. On a probe
region each block is divided by its standard error from the spread of its pixels' residuals
against the fitted truth. Nonlinear models through scipy.optimize.least_squares from a few
starting points (the best kept). A model reports chi-square before (``chi2_none``) and after
(``chi2``), the share of the excess chi-square it removes (``explains``: (chi2_none - chi2) /
(chi2_none - n), n the number of residuals, the chi-square noise alone gives) and whether its
residual passes the evidence's own test at the same alpha (``fully_explains``: the noise test's
block and scale tests, or the probe's Sidak-corrected tests).

Parameters pay through AIC (Akaike 1974): AIC = -2 log L + 2 k, with -2 log L = chi2 for models of
the mean (and N log s^2 + chi2 / s^2 for the noise model, which scales the variances). Ranking:
models that fully explain first; in both groups the models of the mean that remove at least
half of the excess chi-square, then the noise family, then the other models of the mean (a
zero-mean error, such as a sub-pixel shift's edges, is also "explained" by larger noise, and any
gross error by a huge factor on the noise; but a mean model that removes little is no better an
answer: measured on a 0.1 px shift, a 0.7 clamp and too few samples, bench_diagnosis); fewest
parameters next, then by chi-square removed
less 2 k (the AIC difference against "no model" on the same evidence, ``delta_aic``). A failure
whose best model does not fully explain it is reported as "no model explains it" (the best
partial model is named beside it, with what it leaves: its residual's chi-square against the n
that noise alone gives, and the share it explains to the first digit that differs from 100 %).

Evidence (issue 40): a model is fitted only with more residuals than parameters and, for the
cluster-robust standard errors, more blocks (clusters) than parameters (``check_evidence``: the
sandwich has rank at most G - 1, and with one block of 3 residuals a per-channel scale fitted a
constant grey render exactly, "+- 0.000000"); a fit whose standard error is 0 or below the fit's
rounding (SE_RESOLVED) is not used either. Such models are listed in ``not_fitted`` with why, and
the text says how many were left out. A proposed known_deviations.toml entry needs a finite scale
inside PLAUSIBLE_SCALE (``plausible``).
"""
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

MAX_SHOWN = 5  # models kept in metrics.json, best first
# the reference as the best model predicts the render (beside the render in the report's "why"
# view): written when a model on the reference evidence fully explains the failure
CORRECTED = "diagnosis_model.exr"
CRITERION = "AIC (chi2 + 2 k)"
NOISE_FAMILY = "noise"  # models of the variances (noise.py): ranked after the models of the mean that remove SUBSTANTIAL
SUBSTANTIAL = 0.5  # share of the excess chi-square a model of the mean must remove to rank before the noise family
# A standard error below this share of its value is the fit's rounding, not a measurement (the
# square root of double precision's epsilon: what a least-squares fit resolves, Nocedal & Wright
# 2006, 8.1): it is never reported as a standard error, and such a fit is not used (issue 40)
SE_RESOLVED = float(np.sqrt(np.finfo(np.float64).eps))
# A proposed known deviation's scale must be a factor a renderer's conventions can introduce: the
# largest in the catalogue's families is the luminous efficacy, 683 lm/W (photometric units where
# radiometric were due), then 4 pi and pi (per steradian, per area); 1000 either way bounds them,
# and a scale outside (a black render fitted 1.3e-26, issue 40) is no deviation to record
PLAUSIBLE_SCALE = (1e-3, 1e3)
# the checks each kind of evidence speaks to: a model is fitted only when one of them failed (a
# passing check is never diagnosed, and a known render pays only for what failed)
EVIDENCE_CHECKS = {"reference": ("noise test",), "probe:ggx": ("ggx *", "beckmann *"),
                   "reference+ggx": ("noise test", "ggx *", "beckmann *"), "probe:lambert": ("lambert *",),
                   "probe:fresnel": ("brewster *", "reflection *"), "probe:lone": ("lone *",),
                   "probe:airy": ("airy film *",), "probe:prism": ("prism *",),
                   "probe:white furnace": ("ggx white furnace *", "beckmann white furnace *")}


@dataclass
class Model:
    name: str
    family: str
    params: tuple          # names of the fitted parameters ("" units in the name)
    evidence: str          # "reference" or "probe:<kind>"
    explanation: str       # one line for the user
    fit: Callable          # Evidence -> Fit or None
    deviation: Optional[Callable] = None  # Fit -> known_deviations.toml fields (scale, observer) or None
    slow: bool = False     # a nonlinear fit over images or a quadrature: fitted for failed renders only


@dataclass
class Fit:
    values: list           # fitted parameter values (as many as Model.params, or reported extras)
    se: list               # their standard errors
    chi2: float
    chi2_none: float
    n: int
    k: int                 # parameters that pay (a reported value may be a check, not a fit)
    fully: bool
    note: str = ""
    minus2logl: Optional[float] = None  # when it is not chi2 (the noise model)
    corrected: Optional[np.ndarray] = field(default=None, repr=False)  # the render corrected by the fit

    @property
    def aic(self):
        return (self.chi2 if self.minus2logl is None else self.minus2logl) + 2 * self.k

    @property
    def explains(self):
        excess = self.chi2_none - self.n
        if excess <= 0 or self.minus2logl is not None:  # a model of the variances removes no chi-square of the mean
            return None
        return float(np.clip((self.chi2_none - self.chi2) / excess, 0.0, 1.0))


def registry():
    """Every model of the catalogue, family by family."""
    from . import image, materials, noise, polarisation, spectral
    return [*image.MODELS, *polarisation.MODELS, *spectral.MODELS, *materials.MODELS, *noise.MODELS]


class Evidence:
    """What the models fit: the noise test's blocks (render against the reference at this
    resolution) and the render's pixels for the probes. Built by the verdict for a failing (or
    known/fixed) check; ``ztest`` and ``at`` are None when there was no noise test."""

    def __init__(self, entry, scene, names, image, stderr, passes, at=None, ztest=None, picked=None):
        self.entry, self.scene, self.names, self.image = entry, scene, list(names), image
        self.stderr, self.passes, self.at, self.ztest = stderr, passes, at, ztest
        self.picked = picked  # (names, render, stderr) on the channels the reference shares
        self._edges = None
        self.quick = False  # set by diagnose: the slow models (and recomputed probes) left out
        self.cache = {}     # what several models share (a probe computed again once)

    # -- the reference evidence ------------------------------------------------------------------
    @property
    def has_reference(self):
        return self.ztest is not None and self.at is not None and self.ztest.diff is not None

    @property
    def ref_names(self):
        return self.picked[0]

    @property
    def ref_mean(self):
        return self.at.mean

    def edges(self):
        if self._edges is None:
            from .. import compare
            h, w = self.at.mean.shape[:2]
            ey, ex = compare.block_edges(h, self.ztest.block), compare.block_edges(w, self.ztest.block)
            n = compare.block_sums(np.ones((h, w, 1)), ey, ex)
            self._edges = (ey, ex, n)
        return self._edges

    def blocks(self, pixels):
        from .. import compare
        ey, ex, n = self.edges()
        return compare.block_sums(np.asarray(pixels, dtype=np.float64), ey, ex) / n

    @property
    def render_blocks(self):
        return self.ztest.diff + self.ztest.ref_block_mean

    def fit_residual(self, predicted):
        """Block residuals of the render against ``predicted`` (the render as the model predicts it
        from the reference, per pixel) divided by the standard error the reference predicts
        (the scale test's V_b: weights that do not depend on the render's noise, so they cannot
        bias the fit; batch/verdict/compare.py), flattened. What the parameters are fitted on."""
        d = self.render_blocks - self.blocks(predicted)
        v = self.ztest.var_model if self.ztest.var_model is not None else self.ztest.var
        return (d / np.sqrt(v)).ravel()

    def var_under(self, predict, x):
        """The block variances of the difference against ``predict(x, ev)``: the render's own
        (as the noise test has it) plus the reference's carried through the model (its pixel
        standard error sigma mapped as (pred(m + sigma) - pred(m - sigma)) / 2: exact for linear
        models and pixel maps, first order for curves)."""
        zt = self.ztest
        if zt.var_ref is None:
            return zt.var
        sigma = np.sqrt(self.at.var_of_mean)
        try:
            up, down = predict(x, _Shifted(self, sigma)), predict(x, _Shifted(self, -sigma))
        except Exception:  # noqa: BLE001 - a model that cannot take it: the reference's noise unchanged
            return zt.var
        if up is None or down is None:
            return zt.var
        ey, ex, n = self.edges()
        from .. import compare
        v_ref = compare.block_sums(((up - down) / 2) ** 2, ey, ex) / n ** 2
        return zt.var - zt.var_ref + v_ref

    def residual(self, predicted, var=None):
        """Block residuals against ``predicted`` in standard errors (the noise test's, or ``var``)."""
        d = self.render_blocks - self.blocks(predicted)
        return (d / np.sqrt(self.ztest.var if var is None else var)).ravel()

    def passes_noise_test(self, predicted, var_factor=1.0, var=None):
        """Would the render pass the noise test (block and scale tests, same alpha) against
        ``predicted``?"""
        d = self.render_blocks - self.blocks(predicted)
        block_ok, sc = self.ztest._judge(d, (self.ztest.var if var is None else var) * var_factor)
        return bool(block_ok and (sc is None or sc["pass"]) and self.ztest.finite)

    def chi2_none(self):
        return float(np.sum(self.ztest.diff ** 2 / self.ztest.var))


class _Shifted:
    """An Evidence whose reference mean is moved by ``delta`` (to carry its noise through a model)."""

    def __init__(self, ev, delta):
        self._ev, self.ref_mean = ev, ev.ref_mean + delta

    def __getattr__(self, name):
        return getattr(self._ev, name)


# -- fitting ---------------------------------------------------------------------------------------
class TooLittleEvidence(Exception):
    """A model with at least as many parameters as the evidence has residuals (or, for the
    cluster-robust standard errors, clusters): its fit is exact whatever the truth, and its
    standard errors 0 (one block of 3 residuals fitted a per-channel scale "+- 0.000000" to a
    constant grey render, issue 40). The model is not fitted; the diagnosis says why."""


def check_evidence(n, k, clusters=None):
    """Raise TooLittleEvidence unless ``n`` residuals (in ``clusters`` clusters) can fit ``k``
    parameters with a standard error: n > k, and clusters > k (the cluster-robust sandwich has
    rank at most clusters - 1: the scores sum to 0 at the optimum)."""
    if k <= 0:
        return
    if n <= k:
        raise TooLittleEvidence(f"{n} residuals for {_count(k, 'parameter')}")
    if clusters is not None and clusters <= k:
        raise TooLittleEvidence(f"{n} residuals in {_count(clusters, 'block')} (independent clusters) "
                                f"for {_count(k, 'parameter')}")


def _count(n, what):
    return f"{n} {what}" + ("" if n == 1 else "s")


def least_squares(residual, starts, bounds=None, var_ratio=None, channels=1):
    """(best x, its standard errors, chi2) of sum(residual(x)^2) from several starting points
    (scipy.optimize.least_squares, trust region); se from (J^T J)^-1 at the optimum, or, with
    ``var_ratio`` (each residual's true variance over the one it was divided by), from the
    sandwich A^-1 J^T diag(var_ratio) J A^-1 with A = J^T J (weights that are not the inverse
    variances still give the right standard error: Huber 1967, White 1980); ``var_ratio =
    "residuals"``: the residuals at the optimum stand for their variances, clustered by block
    (``channels`` consecutive residuals, a block's colour channels, are one cluster: a path
    tracer's R, G and B come from the same paths and are strongly correlated), with the CR1
    small-sample factor G / (G - 1) (n - 1) / (n - k) (the cluster-robust sandwich of Liang and
    Zeger 1986: right whatever the blocks' variances and the channels' correlation). Raises
    TooLittleEvidence where the residuals (or clusters) are not more than the parameters."""
    from scipy import optimize
    starts = list(starts)
    if starts:
        try:
            r0 = np.asarray(residual(np.asarray(starts[0], dtype=np.float64)), dtype=np.float64).ravel()
        except (ValueError, np.linalg.LinAlgError):
            r0 = None
        if r0 is not None:
            k = len(starts[0])
            check_evidence(r0.size, k, r0.size // max(channels, 1) if isinstance(var_ratio, str) else None)
    best = None
    for x0 in starts:
        kw = {"bounds": bounds} if bounds is not None else {}
        try:
            r = optimize.least_squares(residual, np.asarray(x0, dtype=np.float64), x_scale="jac", **kw)
        except (ValueError, np.linalg.LinAlgError):
            continue
        if best is None or r.cost < best.cost:
            best = r
    if best is None:
        return None
    jac = best.jac
    jtj = jac.T @ jac
    try:
        cov = np.linalg.pinv(jtj)
        if isinstance(var_ratio, str):
            n, k = best.fun.size, len(best.x)
            scores = (jac * best.fun[:, None]).reshape(-1, channels, len(best.x)).sum(axis=1)
            g = scores.shape[0]
            factor = g / max(g - 1, 1) * (n - 1) / max(n - k, 1)
            cov = cov @ (scores.T @ scores) @ cov * factor
        elif var_ratio is not None:
            cov = cov @ (jac.T @ (jac * np.asarray(var_ratio).ravel()[:, None])) @ cov
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    except np.linalg.LinAlgError:
        se = np.full(len(best.x), np.inf)
    return best.x, se, float(2 * best.cost)


def reference_model(predict, starts=None, bounds=None, k=None):
    """A fit function on the reference evidence: ``predict(x, ev)`` is the render as the model
    predicts it from the reference's pixels (x: the parameters; [] for a model without any).
    Fitted with the reference's weights (``fit_residual``), standard errors by the sandwich on the
    noise test's variances, judged (chi-square, fully explains) on the noise test's variances with
    the reference's noise carried through the model."""
    def fit(ev):
        if not ev.has_reference:
            return None
        if not starts:
            pred = predict([], ev)
            if pred is None:
                return None
            var = ev.var_under(predict, [])
            r = ev.residual(pred, var)
            return Fit([], [], float(r @ r), ev.chi2_none(), r.size, 0, ev.passes_noise_test(pred, var=var),
                       corrected=pred)
        if predict(_first(starts, ev), ev) is None:
            return None
        found = least_squares(lambda x: ev.fit_residual(predict(x, ev)), starts(ev) if callable(starts) else starts,
                              bounds, var_ratio="residuals", channels=ev.ztest.diff.shape[-1])
        if found is None:
            return None
        x, se, _ = found
        pred = predict(x, ev)
        var = ev.var_under(predict, x)
        r = ev.residual(pred, var)
        return Fit(list(map(float, x)), list(map(float, se)), float(r @ r), ev.chi2_none(), r.size,
                   len(x) if k is None else k, ev.passes_noise_test(pred, var=var), corrected=pred)
    return fit


def _first(starts, ev):
    return (starts(ev) if callable(starts) else starts)[0]


def region_blocks(mask, block):
    """The whole-pixel blocks of a probe region: [(y0, y1, x0, x1, selection)] with at least
    MIN_PIXELS pixels each (the noise test's tiling, as the GGX probe cuts its plates)."""
    from .. import compare
    from ..probes import MIN_PIXELS
    h, w = mask.shape
    ey, ex = compare.block_edges(h, block), compare.block_edges(w, block)
    out = []
    for y0, y1 in zip(ey[:-1], ey[1:]):
        for x0, x1 in zip(ex[:-1], ex[1:]):
            sel = mask[y0:y1, x0:x1]
            if sel.sum() >= MIN_PIXELS:
                out.append((y0, y1, x0, x1, sel))
    return out


class RegionEvidence:
    """A probe region's blocks: the render's block means and their standard errors from the
    spread of the residuals against the declared truth (``expected0``, per pixel), kept fixed while
    a model's parameters move (weighted least squares with known weights)."""

    def __init__(self, measured, expected0, mask, block):
        self.blocks = region_blocks(mask, block)
        self.measured = measured
        self.reweight(expected0)

    def reweight(self, expected):
        """The blocks' standard errors from the spread of the residuals against ``expected``."""
        measured = self.measured
        m, se, dof = [], [], []
        for y0, y1, x0, x1, sel in self.blocks:
            px = measured[y0:y1, x0:x1][sel].astype(np.float64)
            r = px - expected[y0:y1, x0:x1][sel]
            m.append(px.mean(axis=0))
            se.append(np.maximum(r.std(axis=0, ddof=1) / np.sqrt(len(px)), 1e-300))
            dof.append(np.full(px.shape[1], len(px) - 1.0))
        self.mean, self.se, self.dof = np.array(m), np.array(se), np.array(dof)

    def __len__(self):
        return len(self.blocks)

    def expected(self, image):
        return np.array([image[y0:y1, x0:x1][sel].mean(axis=0) for y0, y1, x0, x1, sel in self.blocks])

    def residual(self, image):
        return ((self.mean - self.expected(image)) / self.se).ravel()

    def passes(self, image):
        from .. import stats
        e = self.expected(image)
        return stats.compare_means(self.mean.ravel(), e.ravel(), self.se.ravel(), dof=self.dof.ravel(),
                                   tests=self.mean.size)["pass"]


def region_fit(region, predict, starts, bounds=None, k=None):
    """Fit ``predict(x) -> expected image`` to a RegionEvidence (no parameters when ``starts`` is
    empty; ``predict([])`` is then the model's truth). The chi-square before is the declared
    truth's (``predict(None)``)."""
    if not starts:
        img = predict([])
        region.reweight(img)
        r0 = region.residual(predict(None))
        r = region.residual(img)
        return Fit([], [], float(r @ r), float(r0 @ r0), r.size, 0, region.passes(img))
    found = least_squares(lambda x: region.residual(predict(x)), starts, bounds)
    if found is None:
        return None
    channels = region.mean.shape[-1]
    # the spread inside a block against a wrong truth holds the truth's own shape, not noise:
    # the standard errors are taken again against the fitted truth, and the fit repeated on them
    region.reweight(predict(found[0]))
    found = least_squares(lambda x: region.residual(predict(x)), [found[0]], bounds, var_ratio="residuals",
                          channels=channels) or found
    x, se, chi2 = found
    r0 = region.residual(predict(None))
    return Fit(list(map(float, x)), list(map(float, se)), chi2, float(r0 @ r0), r0.size,
               len(x) if k is None else k, region.passes(predict(x)))


def channel_parts(names):
    """Per channel: (colour index 0-2, Stokes index or None) for R, G, B and S<k>.<colour>."""
    out = []
    for n in names:
        if "." in n and n[0] == "S" and n[1].isdigit():
            out.append(("RGB".index(n[-1]) if n[-1] in "RGB" else 0, int(n[1])))
        else:
            out.append(("RGB".index(n) if n in "RGB" and n else 0, None))
    return out


# -- the diagnosis of one verdict ------------------------------------------------------------------
def failing_checks(entry):
    """The names of the checks of a job record that failed (plain, before any known deviation)."""
    out = [p["name"] for p in entry.get("probes") or [] if p.get("pass") is False]
    if (entry.get("test") or {}).get("pass") is False:
        out.insert(0, "noise test")
    return out


def speaks_to(model, failing):
    import fnmatch
    return any(fnmatch.fnmatchcase(c, p) for c in failing for p in EVIDENCE_CHECKS.get(model.evidence, ("*",)))


def diagnose(ev, models=None, quick=False):
    """The ranked diagnosis of one render (a dict for metrics.json's ``diagnosis``): every model
    whose evidence speaks to a failing check, fitted, ranked (module docstring). ``quick``: only
    the models a known deviation can carry (``Model.deviation``: a scale, an observer, emitter
    units, the illuminant's normalisation) and none of the slow ones: a known or fixed render is
    diagnosed for the record, to say whether the recorded kind of deviation still explains it; the
    default run's Mitsuba renders are known, and must not pay seconds each (measured: with every
    quick model the sRGB curves alone took 2-3 s of a 3.4 s render of macbeth_chart_D65, under load)."""
    import time
    t0 = time.perf_counter()
    failing = failing_checks(ev.entry)
    fits = []
    chosen = [m for m in models or registry() if speaks_to(m, failing)]
    left_out = [m for m in chosen if quick and (m.slow or m.deviation is None)]
    skipped = [m.name for m in left_out]
    ev.quick = quick
    took = {}
    thin = []  # models not fitted: too little evidence for their parameters
    for model in [m for m in chosen if m not in left_out]:
        t = time.perf_counter()
        try:
            # a fit tries parameters far from the answer: overflow and 0/0 there are expected, and
            # a warning in the terminal would read as a fault of the run
            with np.errstate(all="ignore"):
                f = model.fit(ev)
            if f is not None:
                check_evidence(f.n, f.k)
                unresolved = [model.params[i] if i < len(model.params) else f"p{i}" for i in range(f.k)
                              if i < len(f.se) and not _resolved(f.values[i], f.se[i])]
                if unresolved:
                    raise TooLittleEvidence(f"no standard error for {', '.join(unresolved)} "
                                            f"({f.n} residuals for {_count(f.k, 'parameter')})")
        except TooLittleEvidence as why:
            thin.append({"model": model.name, "why": str(why)})
            continue
        except Exception as exc:  # noqa: BLE001 - one model that breaks never takes the verdict down
            fits.append((model, None, f"{type(exc).__name__}: {exc}"))
            continue
        finally:
            took[model.name] = time.perf_counter() - t
        if f is not None:
            fits.append((model, f, None))
    broken = [{"model": m.name, "error": err[:300]} for m, f, err in fits if f is None]
    useful = [(m, f) for m, f, _ in fits if f is not None and f.aic < f.chi2_none]

    def key(mf):
        m, f = mf
        # the noise family ("the differences are noise") explains any error without a bias, and a
        # factor of 600 on the noise "beat" a clamp that removed 99.99 % of the chi-square by AIC;
        # but a model of the mean that removes little of the excess is no better an answer
        # (bench_diagnosis: correlated passes shown as a shift explaining 8 %, a sample count too
        # small "fully explained" by a scale removing 26 %). So, in both groups: models of the mean
        # that explain at least SUBSTANTIAL of the excess chi-square, then the noise family, then
        # the other models of the mean; then the fewest parameters, then by AIC
        if m.family == NOISE_FAMILY:
            tier = 1
        else:
            tier = 0 if (f.explains or 0.0) >= SUBSTANTIAL else 2
        return (not f.fully, tier, f.k if f.fully else 0, f.aic - f.chi2_none)
    useful.sort(key=key)
    ranked = [_record(m, f) for m, f in useful[:MAX_SHOWN]]
    best = useful[0] if useful else None
    out = {"criterion": CRITERION, "models": ranked, "likely": None, "text": "no model explains it",
           "checks": failing, "fitted": len(fits)}
    if best and best[1].fully:
        out["likely"] = best[0].name
        out["text"] = f"likely: {short(ranked[0])}"
        entry = known_deviation_entry(ev.entry, best[0], best[1])
        if entry:
            out["known_deviation"] = entry
    elif ranked:
        out["text"] = f"no model explains it (best: {short(ranked[0])}; {left(ranked[0])})"
    if thin:
        out["not_fitted"] = thin
        if not out["likely"]:
            out["text"] += (f"; {len(thin)} model{'s' if len(thin) > 1 else ''} not fitted, too little evidence "
                            f"({thin[0]['why']})")
    if broken:
        out["errors"] = broken
    if skipped:
        out["skipped"] = skipped
    out["time_s"] = round(time.perf_counter() - t0, 3)
    out["slowest"] = {k: round(v, 3) for k, v in sorted(took.items(), key=lambda kv: -kv[1])[:5]}
    out["_best_fit"] = best[1] if best else None  # in memory only (the corrected image); popped by the caller
    return out


def _record(model, f):
    params = {}
    for i, v in enumerate(f.values):
        name = model.params[i] if i < len(model.params) else f"p{i}"
        se = f.se[i] if i < len(f.se) and _resolved(v, f.se[i]) else None  # never a standard error of 0
        params[name] = [_num(v), None if se is None else _num(se)]
    out = {"model": model.name, "family": model.family, "evidence": model.evidence, "params": params,
           "k": f.k, "chi2": _num(f.chi2), "chi2_none": _num(f.chi2_none), "n": int(f.n),
           "delta_aic": _num(f.aic - f.chi2_none), "explains": f.explains, "fully_explains": bool(f.fully),
           "explanation": model.explanation}
    if f.note:
        out["note"] = f.note
    return out


def _num(x):
    x = float(x)
    return x if np.isfinite(x) else None


def _resolved(v, se):
    """Whether ``se`` is a standard error of ``v`` (finite, and above the fit's rounding: SE_RESOLVED)."""
    return se is not None and np.isfinite(se) and se > SE_RESOLVED * max(abs(v), np.finfo(np.float64).tiny)


def _fmt(v, se):
    """``v +- se`` to se's second significant digit (fixed point from 1e-6 to 10, else
    scientific); ``v`` alone to 4 digits when there is no standard error (never "+- 0")."""
    if se is None or not _resolved(v, se):
        return f"{v:.4g}"
    digits = 1 - int(np.floor(np.log10(se)))
    if 0 <= digits <= 6:
        return f"{v:.{digits}f} +- {se:.{digits}f}"
    mag = int(np.floor(np.log10(abs(v)))) if v else 0
    return f"{v:.{max(1, mag - int(np.floor(np.log10(se))) + 1)}e} +- {se:.1e}"


def share(explains):
    """A share explained as a percentage, to the first digit that differs from 100 % (99.97 %,
    not 100.0 %, for a model that leaves something): "100 %" only when it removes all of the excess."""
    pct = 100 * explains
    if explains >= 1:
        return "100 %"
    for digits in range(1, 12):
        if round(pct, digits) < 100:
            return f"{pct:.{digits}f} %"
    return f"{pct:.12f} %"


def left(record):
    """What a model leaves unexplained, in words: its residual's chi-square against what noise
    alone gives (n, the residuals' number) and that excess's p-value."""
    chi2, n = record.get("chi2"), record.get("n")
    if record.get("family") == NOISE_FAMILY:  # a model of the variances: its chi-square is n by construction
        return "the render still fails its noise test under it"
    if chi2 is None or not n:
        return "its residual still fails the test"
    from scipy import stats as _st
    from ...stat_text import format_p
    p = float(_st.chi2.sf(chi2, n))
    text = f"left: chi-square {chi2:.4g} where noise alone gives {n} +- {np.sqrt(2 * n):.2g}, p {format_p(p)}"
    if chi2 <= n + 2 * np.sqrt(2 * n):
        text += "; its residual still fails the test where it is largest"
    return text


def short(record):
    """One model of a diagnosis as text: "Stokes frame rotated angle_deg 90.0 +- 0.3, explains 99.6 %"."""
    parts = [record["model"]]
    for name, (v, se) in record["params"].items():
        if v is not None:  # "uniform scale 1.02", not "uniform scale scale 1.02"
            parts.append(_fmt(v, se) if record["model"].endswith(name) else f"{name} {_fmt(v, se)}")
    text = " ".join(parts)
    if record.get("explains") is not None:
        text += f", explains {share(record['explains'])}"
    return text


def plausible(fields):
    """Whether a known deviation's fields are a finite, physically plausible value: a scale inside
    PLAUSIBLE_SCALE (positive), with a finite standard error that is not 0 where it was fitted."""
    if "scale" in fields:
        scale, se = fields["scale"], fields.get("scale_se", 0.0)
        if not (np.isfinite(scale) and PLAUSIBLE_SCALE[0] <= scale <= PLAUSIBLE_SCALE[1]):
            return False
        if se is None or not np.isfinite(se) or se < 0:
            return False
    return True


def known_deviation_entry(entry, model, f):
    """A ready known_deviations.toml entry (text) for a model that fully explains a failure and
    that known.py can re-judge (a scale, an observer), else None. For review before adding."""
    if model.deviation is None:
        return None
    fields = model.deviation(f)
    if not fields or not plausible(fields):
        return None
    import datetime
    import json as _json

    def q(text):
        """A TOML basic string: JSON's escapes are TOML's, but TOML has no surrogate escapes (so
        no ensure_ascii) and forbids a raw DEL; a lone surrogate (no character) becomes U+FFFD."""
        text = "".join("\ufffd" if "\ud800" <= c <= "\udfff" else c for c in str(text))
        return _json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")
    failing = failing_checks(entry)
    ident = f"{entry.get('backend')}-{entry.get('scene')}-{model.name}".replace(" ", "-")
    lines = ["[[deviation]]",
             f"id = {q(ident)}",
             f"backend = {q(str(entry.get('backend')))}",
             f"scenes = [{q(str(entry.get('scene')))}]",
             f"modes = [{q(str(entry.get('mode')))}]",
             f"checks = [{', '.join(q(c) for c in failing)}]"]
    for k, v in fields.items():
        lines.append(f"{k} = {q(v) if isinstance(v, str) else repr(float(v))}")
    lines += [f"evidence = {q('diagnosis of ' + str(entry.get('scene')) + ': ' + model.name + ' fully explains the failure')}",
              f"explanation = {q(model.explanation)}",
              f"date = {q(datetime.date.today().isoformat())}"]
    return "\n".join(lines) + "\n"
