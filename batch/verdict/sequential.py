"""Render until decided (``--detect S``, issue 20): a render job renders its ``--passes`` passes,
looks at the noise test, and while the test has not failed and its ``detectable.scale`` (the
smallest uniform radiance scale error detected with 90 % power: batch/verdict/compare.py
``ZTest.detectable``) is above S, doubles its passes (reusing those rendered:
batch/backends/passes.py ``Accumulation``), up to ``--max-passes``.

The looks: pass counts p, 2p, 4p, ... and ``max_passes`` last (``schedule``), so K =
floor(log2(max_passes / p)) + 1 looks at most (one more when max_passes is not p times a power of
two). Repeated looks at a test that may stop on a fail inflate its false alarms (Armitage,
McPherson and Rowe, J. R. Stat. Soc. A 132(2), 1969), so each look tests at alpha / K (Bonferroni
alpha spending, a constant boundary like Pocock's, Biometrika 64(2), 1977, but without his
correlation-based constant): by the union bound, P(any look false-alarms) <= K alpha / K = alpha
whatever the dependence between looks. Why not Pocock's or O'Brien-Fleming's exact boundaries:
they assume the looks' statistics are one Brownian motion sampled at known information fractions;
here the block size of the noise test shrinks as the samples grow (compare.block_size) and the
noise is each render's own estimate (Student t, Welch-Satterthwaite), so the correlation between
looks is not the textbook sqrt(n_i / n_j); Bonferroni needs none of it and is conservative by
the correlation it ignores (with doubling, neighbouring looks share half their passes). Stopping
for power (detectable <= S) never raises the false-alarm rate: it only removes later looks.
The final verdict is the last look's, at alpha / K (the alpha spent per look), so its
``detectable`` is stated at that alpha too.

What a look decides: the noise test's pass or fail (at alpha / K) and the run's detectable scale
(batch/verdict/judge.py ``look``: the noise test's or a radiance probe's figure, the smaller). The
probes' own pass or fail is the final image's only, at their own alpha: one look, but at a
stopping time that depends on the noise test (correlated with the probes) and the probes' noise
estimates; a probe never stops the loop on its own fail, and the union bound over the K possible
stopping points bounds its false alarms by K times its alpha at worst. Not spent here and not
simulated: the guarantee above is the noise test's. A render the noise test does not judge
(no usable reference, one pass of another backend) renders its --passes only.
"""
MAX_PASSES = 16  # default --max-passes


def schedule(passes, max_passes):
    """Pass counts at the looks: passes, 2 passes, 4 passes, ... below max_passes, then max_passes."""
    p, cap = max(1, int(passes)), max(1, int(max_passes))
    if cap <= p:
        return [p]
    out = []
    while p < cap:
        out.append(p)
        p *= 2
    return out + [cap]


def alpha_per_look(alpha, looks):
    """Bonferroni spending (module docstring): alpha / K at every look."""
    return float(alpha) / max(1, int(looks))


def run(render_to, look, passes, max_passes, target, alpha):
    """The sequential procedure. ``render_to(n)`` brings the render to n passes in all;
    ``look(alpha_k)`` judges it at alpha_k and returns (passed: bool or None when not judged,
    detectable scale or None). Returns the record (metrics.json ``sequential``):
    {target, max_passes, planned_looks, alpha, alpha_per_look, spending, looks: [{passes, pass,
    detectable}], stopped: "detectable" | "failed" | "cap" | "not judged"}."""
    plan = schedule(passes, max_passes)
    a = alpha_per_look(alpha, len(plan))
    record = {"target": target, "max_passes": int(max_passes), "planned_looks": len(plan), "alpha": alpha,
              "alpha_per_look": a, "spending": "Bonferroni: alpha / planned looks at every look", "looks": []}
    for i, n in enumerate(plan):
        render_to(n)
        passed, det = look(a)
        record["looks"].append({"passes": n, "pass": passed, "detectable": det})
        if passed is None:
            record["stopped"] = "not judged"
        elif not passed:
            record["stopped"] = "failed"
        elif det is not None and det <= target:
            record["stopped"] = "detectable"
        elif i == len(plan) - 1:
            record["stopped"] = "cap"
        else:
            continue
        break
    return record

