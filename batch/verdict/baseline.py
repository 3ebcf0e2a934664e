"""A run judged against a previous run (``batch/run.py --baseline OUT_PREV``, ``batch/compare_runs.py``):
"did my change alter anything, and where?".

Each job is matched with the previous run's job of the same scene, backend and mode (any spp; a
resolution equal to it or an integer fraction of it either way) and the two renders are judged
against each other, **both on their own noise**, by the block test that judges a render against a
reference (batch/verdict/compare.py ``z_test``, Sidak-corrected) in the pairing that
batch/verdict/references.py ``judge_replacement`` makes for two references: the finer image is
box-filtered to the coarser one's resolution (``reference_at``: pixels are independent, a big pixel
is the mean of its f x f small ones), the coarser image brings its own per-pixel standard error.
Its analytic probes are compared too: a probe whose residual (measured - expected) moved beyond the
two runs' noise, or one that passed in the baseline and fails now where its residuals cannot be
compared. The job's family of tests (the image test and each compared probe) shares the run's alpha
by a Sidak split, so a job that did not change is called ``changed`` with probability alpha.

A verdict that flipped (status ok -> failed, the noise test or a probe pass -> FAIL) while the
images agree within noise and no probe's residual moved is not a change: the render sits at the
edge of what its checks detect (a deviation of 0.1 % against a test that detects 0.11 % with 90 %
power fails about half the time), so its verdict follows the seed. The record stays ``same`` and
says so (``unstable``).

The record (``entry["baseline"]``, field names of the helpers' contract):
  run        the baseline folder as the user gave it
  status     same | changed | missing (no such job in the baseline) | unjudged (cannot be compared: reason);
             a job rendered in one run only is changed, one rendered in neither is same when its
             status is (both skipped, say)
  reason     what changed and where, or why it could not be compared
  p_min, threshold   the image test's smallest p and its Sidak threshold
  test       the image test in a job's ``test`` layout: its block test and its scale test (either
             fails it), for batch/records.py ``noise_test_text``
  unstable   for a ``same`` job whose verdicts flipped: "verdict unstable: the deviation 0.10 % is
             at the test's detectable 0.11 % (status ok -> failed, ...; the images agree within
             noise)" (``unstable_text``), also its reason; else null
  ratio      [[mean new / mean baseline, its standard error]] for R, G, B
  detectable the smallest uniform relative scale change of the image that the two-sample test
             detects with 90 % power (``detectable_scale``)
  detectable_exact_reference   the same for this render against an exact reference (no noise of its
             own): ``detectable / detectable_exact_reference`` is how much less two noisy runs see
  zmap       per-block z of new - baseline (EXR, R G B), relative to the run folder
  image      the baseline's render, relative to the baseline folder
  time_ratio [median pass time new / baseline, its standard error] (``time_change``), or null

Nothing here changes a job's own status or the run's exit status: the baseline verdict is beside
the job's verdict (batch/compare_runs.py has an exit status for changes).
"""
import math
from pathlib import Path, PurePosixPath

import numpy as np

from .. import exr, run_folder
from ..markdown import cell as _cell
from ..stat_text import format_z
# compare, references, stats (scipy) and previews (PIL) are imported where they are used: the
# Blender panel reads baseline.how_much and order without them. Reading a run folder (metrics.json,
# a job's render, the baseline records and their images) is batch/run_folder.py's.

POWER = 0.9          # power at which ``detectable`` is quoted
ZMAP, ZMAP_PNG = run_folder.ZMAP, run_folder.ZMAP_PNG  # written here beside each render, found by the reader
STATUSES = ("changed", "unjudged", "missing", "same")  # the order changed-first listings use


def key_of(entry):
    """(scene, backend, mode) of a run entry, or None for an entry that is not a job record."""
    if not isinstance(entry, dict):
        return None
    k = (entry.get("scene"), entry.get("backend"), entry.get("mode"))
    return k if all(isinstance(x, str) or x is None for x in k) and isinstance(k[0], str) and isinstance(k[1], str) else None


class Run:
    """A previous run: its folder, metrics.json and its jobs by (scene, backend, mode)."""

    def __init__(self, folder, given=None):
        self.folder = Path(folder)
        self.given = str(given if given is not None else folder)
        self.data = run_folder.read(self.folder)
        self.options = self.data.get("options") if isinstance(self.data.get("options"), dict) else {}
        self.jobs = {}
        for e in self.data["runs"]:
            k = key_of(e)
            if k is not None:
                self.jobs.setdefault(k, e)

    def match(self, entry):
        """(the baseline's entry or None, why there is none)."""
        k = key_of(entry)
        if k is None:
            return None, "not a job record"
        if k in self.jobs:
            return self.jobs[k], None
        other = sorted(str(m) for (s, b, m) in self.jobs if (s, b) == k[:2])
        return None, (f"no job {k[0]} / {k[1]} {k[2] or ''} in the baseline run {self.given}".replace("  ", " ")
                      + (f" (it has mode {', '.join(other)})" if other else ""))


# -- power ------------------------------------------------------------------------------------------
def block_power(delta, crit):
    """Power of one two-sided block test at critical value ``crit`` when its statistic is normal
    around the noncentrality ``delta``: P(|Z + delta| > crit) (the power function of the two-sided
    z test: Cohen 1988, Statistical Power Analysis, ch. 2)."""
    from scipy import stats as _st
    delta, crit = np.broadcast_arrays(np.asarray(delta, dtype=np.float64), np.asarray(crit, dtype=np.float64))
    return np.clip(_st.norm.sf(crit - delta) + _st.norm.cdf(-crit - delta), 0.0, 1.0)


def detectable_scale(ztest, var=None, power=POWER):
    """The smallest uniform relative scale change s of the image (every pixel times 1 + s) that the
    block test ``ztest`` (compare.ZTest) detects with probability ``power``. In a block b of mean m_b
    the change moves the difference by s m_b, so its statistic has noncentrality s |m_b| / sqrt(v_b)
    (``var``: per-block variance v_b, default the test's own); the blocks are independent (pixels
    are), so the test misses it with probability prod_b (1 - power_b(s)) (``block_power`` at the
    test's per-block Sidak critical value of Student's t with the block's degrees of freedom). Bisection on s in (0, 1] (the power grows with s);
    None when even s = 1 (100 %) is not detected with that power."""
    from scipy import stats as _st
    if ztest is None or ztest.diff is None or ztest.diff.size == 0:
        return None
    m = np.abs(np.asarray(ztest.ref_block_mean, dtype=np.float64)).ravel()
    v = np.asarray(ztest.var if var is None else var, dtype=np.float64).ravel()
    dof = np.broadcast_to(np.asarray(ztest.dof, dtype=np.float64), ztest.diff.shape).ravel()
    ok = (v > 0) & (m > 0)
    if not ok.any():
        return None
    m, v, dof = m[ok], v[ok], dof[ok]
    dfs = np.where(np.isfinite(dof) & (dof < 1e7), np.maximum(dof, 1.0), np.inf)
    crit = np.where(np.isfinite(dfs), _st.t.isf(ztest.threshold / 2.0, np.where(np.isfinite(dfs), dfs, 1.0)),
                    _st.norm.isf(ztest.threshold / 2.0))
    # the blocks that can matter: the most sensitive first (all of them when there are few)
    sens = m / np.sqrt(v)
    keep = np.argsort(-sens)[:4096]
    m, v, dfs, crit, sens = m[keep], v[keep], dfs[keep], crit[keep], sens[keep]

    def power_at(s):
        # the statistic as normal around its noncentrality, against the test's own (Student t)
        # critical value: the Satterthwaite degrees of freedom estimated from few passes are biased
        # low, and a noncentral t with them puts too much of its tail beyond the critical value
        # (measured: 78 % instead of 90 % with 4 passes; tests/verdict/test_baseline.py)
        p = block_power(s * sens, crit)
        return 1.0 - float(np.exp(np.sum(np.log1p(-np.minimum(p, 1 - 1e-16)))))

    if power_at(1.0) < power:
        return None
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if power_at(mid) < power else (lo, mid)
    return hi


def detectable_pair(ztest, exact_var):
    """(what the two-sample test detects with POWER, what it would against an exact reference).
    The first is the noise test's own figure (compare.ZTest.detectable: its block and scale tests
    at their shares of alpha); the second scales it by how much less the block test alone sees
    with both noises than with the new image's alone (``detectable_scale`` with ``exact_var``)."""
    own = ztest.detectable() if hasattr(ztest, "detectable") else None
    block_both, block_exact = detectable_scale(ztest), detectable_scale(ztest, var=exact_var)
    det = own["scale"] if own else block_both
    if det is None:
        return None, None
    ratio = block_exact / block_both if block_both and block_exact else None
    return det, (det * ratio if ratio else None)


def _own_block_var(result, new_var_of_mean):
    """Per-block variance of the new image's own block mean at the test's resolution and blocks
    (for the figure against an exact reference), in the layout of the test's ``var``."""
    from . import compare
    zt, at = result["_ztest"], result["_at"]
    per_pixel = new_var_of_mean if result["_new_is_test"] else at.var_of_mean
    shape = per_pixel.shape
    ey, ex = compare.block_edges(shape[0], zt.block), compare.block_edges(shape[1], zt.block)
    n = compare.block_sums(np.ones(shape[:2] + (1,)), ey, ex)
    floor = (1e-4 * max(float(np.mean(np.abs(at.mean))), 1e-12)) ** 2
    return compare.block_sums(np.where(np.isfinite(per_pixel), per_pixel, 0.0), ey, ex) / n**2 + floor


# -- time -------------------------------------------------------------------------------------------
def _log_median_se(times):
    """(log of the median pass time, its standard error, its degrees of freedom) from one job's
    pass times. The median's standard error is sqrt(pi / 2) s / sqrt(n) for n >= 3 (its asymptotic
    variance under normal errors, pi sigma^2 / (2 n): Kendall and Stuart, The Advanced Theory of
    Statistics, vol. 1, 10.10), s / sqrt(n) for n = 2 (the median is the mean), taken on log times
    so that the ratio's error is relative; None with a single pass."""
    t = np.log(np.asarray(times, dtype=np.float64))
    n = t.size
    if n < 2:
        return float(np.median(t)), None, 0
    s = float(np.std(t, ddof=1))
    se = s / math.sqrt(n) * (math.sqrt(math.pi / 2) if n >= 3 else 1.0)
    return float(np.log(np.median(np.exp(t)))), se, n - 1


PASS_SECONDS = (1e-6, 1e7)  # a pass time outside this range (a microsecond to 116 days) is not a measurement


def _times(entry):
    t = entry.get("pass_times") if isinstance(entry, dict) else None
    if not isinstance(t, list) or not t or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                    and PASS_SECONDS[0] <= x <= PASS_SECONDS[1] for x in t):
        return None
    return t


def times_problem(entry):
    """Why a record's ``pass_times`` (present) is not what a run writes, or None (also when absent)."""
    t = entry.get("pass_times") if isinstance(entry, dict) else None
    if t is None or _times(entry) is not None:
        return None
    return (f"pass_times is not a non-empty list of seconds in [{PASS_SECONDS[0]:g}, {PASS_SECONDS[1]:g}] "
            f"({str(t)[:80]})")


def time_change(old_entry, new_entry, alpha=0.01):
    """The render time of a job against its baseline, from each pass's time: ratio of the median
    pass times with its standard error (delta method on the logs: se(r) = r sqrt(se_new^2 +
    se_old^2), JCGM 100:2008 (GUM) 5.1.2), the test of log r = 0 (Student's t, Welch-Satterthwaite
    degrees of freedom) and the sentence "slower by X % (+- Y)" / "faster by ..." only when that test
    rejects at ``alpha``. None without pass times on both sides. The spread is the pass-to-pass
    spread within each run: a machine busier during one whole run is not in it."""
    from . import stats
    to, tn = _times(old_entry), _times(new_entry)
    if to is None or tn is None:
        return None
    lo, se_o, d_o = _log_median_se(to)
    ln, se_n, d_n = _log_median_se(tn)
    r = math.exp(ln - lo)
    out = {"ratio": r, "se": None, "p": None, "text": None, "passes": [len(to), len(tn)]}
    if se_o is None or se_n is None:
        out["why"] = "a single pass: no spread to judge the ratio by"
        return out
    se_log = math.sqrt(se_o**2 + se_n**2)
    out["se"] = r * se_log
    if se_log == 0:
        out["why"] = "no spread between passes"
        return out
    dof = float(stats.satterthwaite_dof([se_o**2, se_n**2], [d_o, d_n]))
    p = float(stats.two_sided_p(math.log(r) / se_log, dof))
    out["p"] = p
    if p < alpha:
        word = "slower" if r > 1 else "faster"
        out["text"] = f"{word} by {abs(r - 1) * 100:.0f} % (+- {out['se'] * 100:.0f})"
    else:
        out["why"] = f"within the passes' spread (ratio {r:.2f} +- {out['se']:.2f}, p = {p:.2g})"
    return out


# -- probes -----------------------------------------------------------------------------------------
def _probe_stat(p):
    s = p.get("stat") if isinstance(p, dict) else None
    if not isinstance(s, dict):
        return None
    try:
        arr = {k: np.atleast_1d(np.asarray(s[k], dtype=np.float64)) for k in ("measured", "expected", "se")}
    except (KeyError, TypeError, ValueError):
        return None
    if len({a.shape for a in arr.values()}) != 1:
        return None
    if "dof" in s:
        try:
            arr["dof"] = np.broadcast_to(np.asarray(s["dof"], dtype=np.float64), arr["measured"].shape)
        except (TypeError, ValueError):
            return None
    return arr


def compare_probes(old_entry, new_entry):
    """[{name, old, new (pass), stat: old and new residuals compared or None}] for every probe of
    either run; the statistics are filled in by ``judge_probes``."""
    old = {p.get("name"): p for p in old_entry.get("probes") or [] if isinstance(p, dict)}
    new = {p.get("name"): p for p in new_entry.get("probes") or [] if isinstance(p, dict)}
    out = []
    for name in list(new) + [n for n in old if n not in new]:
        o, n = old.get(name), new.get(name)
        out.append({"name": str(name), "old": None if o is None else o.get("pass"),
                    "new": None if n is None else n.get("pass"), "_stats": (_probe_stat(o), _probe_stat(n))})
    return out


def judge_probes(rows, alpha):
    """Each probe's residual (measured - expected) now against the baseline's, on both runs'
    standard errors (stats.compare_means, Sidak over the probe's own tests at ``alpha``)."""
    from . import stats
    for row in rows:
        so, sn = row.pop("_stats")
        row["moved"] = None
        if so is None or sn is None or so["measured"].shape != sn["measured"].shape:
            continue
        ro, rn = so["measured"] - so["expected"], sn["measured"] - sn["expected"]
        se = np.sqrt(so["se"] ** 2 + sn["se"] ** 2)
        dof = None
        if "dof" in so and "dof" in sn:
            dof = stats.satterthwaite_dof(np.stack([so["se"] ** 2, sn["se"] ** 2]), np.stack([so["dof"], sn["dof"]]))
        r = stats.compare_means(rn, ro, se, dof=dof, alpha=alpha)
        row.update(moved=not r["pass"], z=r["z"], p=r["p"], threshold=r["threshold"])
    return rows


def _families(rows):
    return 1 + sum(1 for r in rows if r["_stats"][0] is not None and r["_stats"][1] is not None)


# -- verdicts that flipped while the images agree ---------------------------------------------------
DECIDED = ("ok", "failed", "known", "fixed")  # statuses of a judged render (batch/verdict/status.py)


def _verdict_word(passed):
    return {True: "pass", False: "FAIL", None: "not judged"}.get(passed, str(passed))


def _test_pass(entry):
    t = entry.get("test")
    return t.get("pass") if isinstance(t, dict) else None


def verdict_flips(old_entry, new_entry, rows=None):
    """The verdicts of a job that differ between the baseline and this run: [{"what", "old", "new",
    "decided", "text"}] for its status, its noise test against the reference and each probe present
    in both (``rows``: ``compare_probes`` judged by ``judge_probes``, for whether the probe's residual
    moved). ``decided``: both sides are verdicts of a judged render (a status in DECIDED, pass or
    FAIL) and, for a probe, its residuals were compared and did not move beyond noise; a flip that
    is not decided (ok -> unjudged, a probe without statistics, ok -> failed with no check flipped)
    is a change in itself."""
    out = []
    to, tn = _test_pass(old_entry), _test_pass(new_entry)
    if to != tn:
        out.append({"what": "noise test", "old": to, "new": tn,
                    "decided": isinstance(to, bool) and isinstance(tn, bool),
                    "text": f"noise test against the reference {_verdict_word(to)} -> {_verdict_word(tn)}"})
    po, pn = _probe_passes(old_entry), _probe_passes(new_entry)
    moved = {str(r.get("name")): r.get("moved") for r in rows or [] if isinstance(r, dict)}
    for name in pn:
        if name not in po or po[name] == pn[name]:
            continue  # a probe new or gone is the caller's to list
        a, b = po[name], pn[name]
        out.append({"what": f"probe {name}", "name": name, "old": a, "new": b,
                    "decided": isinstance(a, bool) and isinstance(b, bool) and moved.get(name) is False,
                    "text": f"probe {name} {_verdict_word(a)} -> {_verdict_word(b)}"})
    so, sn = old_entry.get("status"), new_entry.get("status")
    if so != sn:
        # a status follows its checks (and, for known and fixed, their re-judging under a recorded
        # deviation, which is noisy too): ok -> failed with no check flipped is no seed's doing
        noisy = any(f["decided"] for f in out) or any(s in ("known", "fixed") for s in (so, sn))
        out.insert(0, {"what": "status", "old": so, "new": sn, "decided": so in DECIDED and sn in DECIDED and noisy,
                       "text": f"status {so} -> {sn}"})
    return out


def _probe_passes(entry):
    p = entry.get("probes")
    return {str(x.get("name")): x.get("pass") for x in p if isinstance(x, dict)} if isinstance(p, list) else {}


def _pooled(values):
    """Inverse-variance mean of [(estimate, standard error)] (the estimates of one quantity from the
    two runs), or None."""
    good = [(v, s) for v, s in values if isinstance(v, (int, float)) and isinstance(s, (int, float))
            and math.isfinite(v) and math.isfinite(s) and s > 0]
    if not good:
        return None
    w = [1.0 / s**2 for _, s in good]
    return sum(wi * v for wi, (v, _) in zip(w, good)) / sum(w), 1.0 / math.sqrt(sum(w))


def scale_deviation(old_entry, new_entry):
    """The render's uniform scale deviation from the reference as both runs measure it: per channel
    the two runs' scale test estimates (batch/verdict/compare.py ``scale_stats``: s and its standard
    error) pooled by inverse variance, |s - 1| of the channel whose pooled estimate lies most standard
    errors from 1; None without a scale test in both runs."""
    scs = [(e.get("test") or {}).get("scale_test") if isinstance(e.get("test"), dict) else None
           for e in (old_entry, new_entry)]
    if not all(isinstance(sc, dict) and isinstance(sc.get("s"), list) and isinstance(sc.get("se"), list) for sc in scs):
        return None
    best = None
    for c in range(min(len(sc["s"]) for sc in scs)):
        pooled = _pooled([(sc["s"][c], sc["se"][c] if c < len(sc["se"]) else None) for sc in scs])
        if pooled is not None and (best is None or abs(pooled[0] - 1) / pooled[1] > best[1]):
            best = (abs(pooled[0] - 1), abs(pooled[0] - 1) / pooled[1])
    return None if best is None else best[0]


def _noise_test_detectable(entry):
    """The smallest uniform scale error the job's noise test detects with 90 % power (its block and
    scale tests' best: metrics.json ``detectable.tests``), else the run's ``detectable.scale``."""
    det = entry.get("detectable") if isinstance(entry.get("detectable"), dict) else {}
    tests = det.get("tests") if isinstance(det.get("tests"), dict) else {}
    found = [v for v in tests.values() if isinstance(v, (int, float)) and v > 0]
    if found:
        return min(found)
    return det.get("scale") if isinstance(det.get("scale"), (int, float)) and det["scale"] > 0 else None


def _probe_deviation(name, old_entry, new_entry):
    """(|relative residual| of a probe pooled over both runs, at its element most standard errors
    from what it expects; its own detectable figure from the new run) or Nones."""
    stats = []
    for e in (old_entry, new_entry):
        probes = e.get("probes") if isinstance(e.get("probes"), list) else []
        p = next((p for p in probes if isinstance(p, dict) and str(p.get("name")) == name), None)
        stats.append(_probe_stat(p))
    det = (new_entry.get("detectable") or {}).get("probes") if isinstance(new_entry.get("detectable"), dict) else None
    det = det.get(name) if isinstance(det, dict) else None
    if any(s is None for s in stats) or stats[0]["measured"].shape != stats[1]["measured"].shape:
        return None, det
    best = None
    for i in range(stats[0]["measured"].size):
        rel = [((s["measured"].flat[i] - s["expected"].flat[i]) / s["expected"].flat[i],
                s["se"].flat[i] / abs(s["expected"].flat[i])) for s in stats if s["expected"].flat[i] != 0]
        pooled = _pooled(rel) if len(rel) == 2 else None
        if pooled is not None and (best is None or abs(pooled[0]) / pooled[1] > best[1]):
            best = (abs(pooled[0]), abs(pooled[0]) / pooled[1])
    return (None if best is None else best[0]), det


def _percent(x):
    text = f"{100 * x:#.2g}"
    return text.rstrip(".")


def _at(dev, det):
    """Where a deviation lies against what the test detects with 90 % power: below (under half of
    it: the test seldom fails such a render, its flip was a rare draw), at (half to 1.5 times it:
    the test fails such a render with some probability between rarely and nearly always, so with
    the seed), above."""
    r = dev / det
    return "below" if r < 0.5 else "at" if r <= 1.5 else "above"


def unstable_text(old_entry, new_entry, flips):
    """The sentence for verdicts that flipped while the images agree within noise: "verdict
    unstable: the deviation 0.10 % is at the test's detectable 0.11 % (status ok -> failed, noise
    test against the reference pass -> FAIL; the images agree within noise)". The deviation is the
    one both runs measure (``scale_deviation``; a probe's: its relative residual pooled over both
    runs), against what the check detects with 90 % power: a check that sits at the edge of its
    power passes or fails with the seed."""
    figures = []
    probe_flips = [f for f in flips if f["what"].startswith("probe ")]
    if any(f["what"] == "noise test" for f in flips) or not probe_flips:
        dev, det = scale_deviation(old_entry, new_entry), _noise_test_detectable(new_entry)
        if dev is not None and det:
            figures.append(f"the deviation {_percent(dev)} % is {_at(dev, det)} the test's detectable {_percent(det)} %")
    for f in probe_flips:
        dev, det = _probe_deviation(f["name"], old_entry, new_entry)
        if dev is not None and det:
            figures.append(f"{f['what']}'s deviation {_percent(dev)} % is {_at(dev, det)} its detectable {_percent(det)} %")
    what = ", ".join(f["text"] for f in flips)
    return ("verdict unstable: " + ("; ".join(figures) + f" ({what}; the images agree within noise)" if figures
                                    else f"{what} while the images agree within noise"))


# -- one job against its baseline ------------------------------------------------------------------
def _ratio_list(ratio):
    return [ratio.get(c) for c in ("R", "G", "B")]


def _record(run, status, reason, **kw):
    rec = {"run": run, "status": status, "reason": reason, "p_min": None, "threshold": None, "ratio": None,
           "detectable": None, "zmap": None, "image": None, "time_ratio": None}
    rec.update(kw)
    return rec


def judge_pair(new_entry, new_folder, old_entry, old_folder, settings, zmap_path, zmap_rel, run_label):
    """The baseline record of ``new_entry`` (a job of the run in ``new_folder``) against
    ``old_entry`` (the matching job of the run in ``old_folder``). ``settings``: alpha, min_samples,
    block (the noise test's, default the runner's). The z-map is written to ``zmap_path`` and
    recorded as ``zmap_rel``; ``run_label``: the baseline folder as the user gave it."""
    from .. import previews
    from . import references, stats
    alpha = settings.get("alpha") or stats.ALPHA
    tc = time_change(old_entry, new_entry, alpha)
    common = {"image": old_entry.get("image") if isinstance(old_entry.get("image"), str) else None,
              "time_ratio": None if tc is None else [tc["ratio"], tc["se"]], "time": tc}
    new_img, old_img = run_folder.Job(new_folder, new_entry).path("render"), run_folder.Job(old_folder, old_entry).path("render")
    for img, entry, which in ((new_img, new_entry, "this run's"), (old_img, old_entry, "the baseline's")):
        if img is None and entry.get("image"):
            return _record(run_label, "unjudged", f"{which} render {str(entry.get('image'))[:200]!r} is not a file "
                           "inside its run folder", **common)
    if new_img is None or old_img is None:  # a render that appeared or went away is a change in itself
        so, sn = old_entry.get("status"), new_entry.get("status")
        if new_img is None and old_img is None:
            return _record(run_label, "same" if so == sn else "changed", f"rendered in neither run (status {so}"
                           + ("" if so == sn else f" -> {sn}") + ")", **common)
        if new_img is None:
            return _record(run_label, "changed", f"rendered in the baseline, not in this run (status {sn}"
                           + (f": {new_entry.get('reason')}" if new_entry.get("reason") else "") + ")", **common)
        return _record(run_label, "changed", f"rendered now, not in the baseline (status {so}"
                       + (f": {old_entry.get('reason')}" if old_entry.get("reason") else "") + ")", **common)
    try:
        # the header first, against the resolution each record gives (a crafted EXR is refused before its pixels)
        n_names, n_img, n_se = exr.read_image_and_stderr(new_img, expect=new_entry.get("resolution"))
        o_names, o_img, o_se = exr.read_image_and_stderr(old_img, expect=old_entry.get("resolution"))
    except Exception as exc:  # noqa: BLE001 - an unreadable image is that job's problem, named
        return _record(run_label, "unjudged", f"cannot read a render: {exc}", **common)
    if n_se is None or o_se is None:
        which = "this run's" if n_se is None else "the baseline's"
        return _record(run_label, "unjudged", f"{which} render has no per-pixel noise (one pass: render with "
                       "--passes >= 2)", **common)
    rows = compare_probes(old_entry, new_entry)
    share = 1.0 - (1.0 - alpha) ** (1.0 / _families(rows))  # Sidak split of the job's alpha
    old = references.Reference(o_names, o_img, o_se, {"spp": _spp(old_entry), "passes": _passes(old_entry)}, old_img)
    new = references.Reference(n_names, n_img, n_se, {"spp": _spp(new_entry), "passes": _passes(new_entry)}, new_img)
    res = references.judge_replacement(old, new, alpha=share, min_samples=settings.get("min_samples"),
                                       block=settings.get("block"), keep=True)
    if not res["comparable"]:
        return _record(run_label, "unjudged", f"cannot be compared with the baseline: {res['reason']}", **common)
    zt = res["_ztest"]
    judge_probes(rows, share)
    n_var = n_se.astype(np.float64) ** 2
    det, det_exact = detectable_pair(zt, _own_block_var(res, n_var))
    zmap_path = Path(zmap_path)
    zmap_path.parent.mkdir(parents=True, exist_ok=True)
    exr.write(zmap_path, zt.zmap[..., :3])
    worst = np.take_along_axis(zt.zmap, np.abs(zt.zmap).argmax(axis=-1)[..., None], axis=-1)[..., 0]
    previews.save_signed(zmap_path.with_name(ZMAP_PNG), worst, scale=6)
    y, x = np.unravel_index(int(np.argmax(np.abs(worst))), worst.shape)
    ratio = _ratio_list(res["ratio"])
    test = zt.as_dict()  # the two-sample noise test, in a job's ``test`` layout (its block and scale tests)
    changes = []
    if not zt.passed:
        from ..records import noise_test_failure  # the part that failed, with its own figures
        changes.append(f"image differs beyond noise: {noise_test_failure(test)} ({zt.blocks} blocks); max |z| = "
                       f"{format_z(zt.z_max, 1)} at pixel ({x}, {y}) of {worst.shape[1]}x{worst.shape[0]}; mean ratio " + ", ".join(
                           f"{c} {r[0]:.4f} +- {r[1]:.4f}" for c, r in zip("RGB", ratio) if r))
    for r in rows:
        if r.get("moved"):
            changes.append(f"probe {r['name']} moved beyond noise (z = {format_z(r['z'], 1)})")
        elif r["old"] is True and r["new"] is False and r.get("moved") is None:  # no residuals to judge it by
            changes.append(f"probe {r['name']} passed in the baseline and fails now")
    status = "changed" if changes else "same"
    reason = "; ".join(changes) + (f"; z-map: {zmap_rel}" if changes else "")
    unstable = None
    flips = verdict_flips(old_entry, new_entry, rows)
    if not changes and flips and all(f["decided"] for f in flips):
        # the verdicts flipped while the images agree within noise: a check at the edge of its power
        unstable = reason = unstable_text(old_entry, new_entry, flips)
    return _record(run_label, status, reason, p_min=zt.p_min, threshold=zt.threshold, ratio=ratio, test=test,
                   unstable=unstable,
                   detectable=det, detectable_exact_reference=det_exact,
                   sees_less=(det / det_exact) if det and det_exact else None,
                   zmap=str(zmap_rel), judged_at=res["judged_at"], z_max=zt.z_max, worst_pixel=[int(x), int(y)],
                   probes=rows, **common)


def _spp(entry):
    v = entry.get("spp")
    return v if isinstance(v, int) and not isinstance(v, bool) and v > 0 else 1


def _passes(entry):
    v = entry.get("passes")
    return v if isinstance(v, int) and not isinstance(v, bool) and v > 0 else 2


def judge_entry(entry, out, base, settings, zmap_root=None, zmap_prefix=""):
    """The baseline record of one run entry of the run in ``out`` against the run ``base`` (a Run).
    The z-map goes beside the render (``zmap_root``/``zmap_prefix``/<render's folder>/, default the
    run folder itself), its path recorded relative to ``zmap_root``."""
    old, why = base.match(entry)
    if old is None:
        return _record(base.given, "missing", why)
    folder = run_folder.job_dir(out, entry) or PurePosixPath("_baseline", "job")
    rel = PurePosixPath(zmap_prefix, *folder.parts, ZMAP) if zmap_prefix else PurePosixPath(*folder.parts, ZMAP)
    root = Path(zmap_root if zmap_root is not None else out)
    try:
        return judge_pair(entry, out, old, base.folder, settings, root / Path(*rel.parts), rel.as_posix(), base.given)
    except Exception as exc:  # noqa: BLE001 - a comparison that breaks is that job's problem, not the run's
        return _record(base.given, "unjudged", f"comparison failed: {type(exc).__name__}: {exc}")


def attach(entry, out, base, settings):
    """``entry`` (a render job's metrics.json record) with its ``baseline`` record (in place)."""
    if entry.get("mode") == "export":
        return entry
    entry["baseline"] = judge_entry(entry, Path(out), base, settings)
    return entry


# -- text ---------------------------------------------------------------------------------------------
def how_much(rec):
    """One line: the ratio per channel, what the test could see, and the time."""
    parts = []
    ratio = rec.get("ratio")
    if isinstance(ratio, list) and any(isinstance(r, list) for r in ratio):
        parts.append("ratio " + ", ".join(f"{c} {r[0]:.4f} +- {r[1]:.4f}" for c, r in zip("RGB", ratio)
                                            if isinstance(r, list) and len(r) == 2 and None not in r))
    det = rec.get("detectable")
    if isinstance(det, (int, float)):
        line = f"detects {det * 100:.2g} % (90 % power)"
        less = rec.get("sees_less")
        if isinstance(less, (int, float)):
            line += f", {less:.2f}x the {rec['detectable_exact_reference'] * 100:.2g} % against an exact reference"
        parts.append(line)
    tc = rec.get("time") if isinstance(rec.get("time"), dict) else None
    if tc and tc.get("text"):
        parts.append(tc["text"])
    return "; ".join(parts)


def shown_status(rec):
    """The word a baseline record is shown with (summary.md, report.html, the panel), as
    compare_runs shows its jobs: its status, or "unstable" for a ``same`` record whose verdicts
    flipped while the images agree within noise (``unstable``): the status stays ``same``, so the
    job is not CHANGED and the exit status not 1 (issue 45 item 6)."""
    status = rec.get("status") if isinstance(rec, dict) else None
    return "unstable" if status == "same" and isinstance(rec.get("unstable"), str) and rec["unstable"] else status


def summary_section(runs):
    """The '## Against the baseline' section of summary.md: changed jobs first, with where (the
    z-map) and how much; empty when no job has a baseline record."""
    recs = [(r, r["baseline"]) for r in runs if isinstance(r, dict) and isinstance(r.get("baseline"), dict)]
    if not recs:
        return ""
    order = {s: i for i, s in enumerate(STATUSES)}
    recs.sort(key=lambda rb: (order.get(rb[1].get("status"), 9), str(rb[0].get("scene")), str(rb[0].get("backend"))))
    count = {}
    for _, b in recs:
        count[shown_status(b)] = count.get(shown_status(b), 0) + 1
    head = ", ".join(f"{count[s]} {s}" for s in STATUSES[:-1] + ("unstable", "same") if s in count)
    out = ["", "## Against the baseline", "",
           f"Baseline: {_cell(recs[0][1].get('run'))}. {head}. Each render judged against the baseline's on both their noises (two-sample block test, "
           "Sidak-corrected), and its probes compared; this does not change a job's status or the exit status "
           "(batch/compare_runs.py has one).", "",
           "| baseline | scene | backend | mode | how much | where (z-map) | reason |", "|---|---|---|---|---|---|---|"]
    for r, b in recs:
        out.append(f"| {_cell(shown_status(b))} | {_cell(r.get('scene'))} | {_cell(r.get('backend'))} | "
                   f"{_cell(r.get('mode') or '')} | {_cell(how_much(b))} | {_cell(b.get('zmap') or '')} | "
                   f"{_cell((b.get('reason') or '')[:300])} |")
    return "\n".join(out) + "\n\n## Jobs\n\n"


# -- the panel's order (its records and images: batch/run_folder.py baseline_records, baseline_image) --
def order(rec):
    """Sort key of a baseline record: changed first (then unjudged, missing, same; none last)."""
    status = rec.get("status") if isinstance(rec, dict) else None
    return STATUSES.index(status) if status in STATUSES else len(STATUSES)

