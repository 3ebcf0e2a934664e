"""sb_fluorescent_path: Mitsuba 3's path tracer (next-event estimation, MIS with the power
heuristic, Russian roulette) plus re-radiation at fluorescent surfaces, in one recorded Dr.Jit
loop (Mitsuba 3 Python integrator of spectral_bench; standalone: imports mitsuba, drjit, numpy).

    <integrator type="sb_fluorescent_path"><integer name="max_depth" value="64"/></integrator>

Fluorescent surfaces are those whose BSDF offers ``elastic_reflectance``,
``reradiation_albedo`` and ``sample_excitation`` (sb_fluorescent_diffuse). Without any, this
integrator computes exactly what Mitsuba's ``path`` does, in the same order.

The estimator. A fluorescent Lambertian surface scatters (spectral_bench's exporters/
fluorescence.py; Mojzik, Fichet and Wilkie 2018, "Handling fluorescence in a uni-directional
spectral path tracer", CGF 37(4): the bispectral rendering equation, whose BRRDF has an elastic
diagonal and an off-diagonal re-radiation)

    L_o(x, w_o, l_o) = integral over w_i of cos(theta_i) / pi
                       [ rho(l_o) L_i(x, w_i, l_o) + integral P(l_i, l_o) L_i(x, w_i, l_i) dl_i ] dw_i.

A camera path carries Mitsuba's wavelengths (four independent lanes, sampled by the sensor over
360-830 nm). At a fluorescent vertex each lane, with its current wavelength l_o, first picks the
event: elastic with probability rho(l_o) / T(l_o), re-radiation with probability A(l_o) / T(l_o),
where A(l_o) = integral P(l_i, l_o) dl_i and T = rho + A is the lane's total albedo. For
re-radiation it draws the excitation wavelength l_i with density P(l_i, l_o) / A(l_o) (a binary
search in the tabulated column, then inversion inside the cell), so l_i may lie below 360 nm. The
lane continues at l' = l_o (elastic) or l_i. In both cases the Monte Carlo weight of the wavelength
choice is the integrand over its density:
    elastic:       rho(l_o) / (rho(l_o) / T)                                  = T(l_o)
    re-radiation:  P(l_i, l_o) / ((A / T) * P(l_i, l_o) / A)                  = T(l_o),
which is the paper's strategy of sampling the wavelength shift in proportion to the re-radiation
(the same estimator as ART 2.1.2's randomWavelengthShift, which implements that paper; read in
ART's ArnColourStandardImplementation.h). The directional part is then an ordinary Lambertian
vertex of albedo T(l_o) seen at l': next-event estimation evaluates the light at l' with BSDF
value T(l_o) cos / pi, BSDF sampling draws cos / pi and weights T(l_o), and both are combined
with the power heuristic exactly as ``path`` does (the direction densities are those of the
diffuse lobe, whatever the event). The estimate is unbiased for every lane: each factor is an
integrand over its own sampling density, chosen before the direction is drawn.

Random numbers: one uniform per lane decides both the event and l_i (u T < rho: elastic;
otherwise the target u T - rho in [0, A) is inverted in the cumulative column).

Wavelengths below 360 nm: Mitsuba's sensor never samples them, but the excitation wavelength
comes from the re-radiation table (down to 300 nm in the scene IR), and the light there is
whatever the scene's spectra say: spectral_bench's writer tabulates every spectrum of a
fluorescent scene from 300 nm for that reason (a spectrum file that starts at 360 nm evaluates
to 0 below it in Mitsuba, which would darken UV-excited fluorescence without any warning).
"""
import drjit as dr
import mitsuba as mi

PLUGIN_NAME = "sb_fluorescent_path"


def mis_weight(pdf_a, pdf_b):
    """Power heuristic, 0 where not finite (as Mitsuba's path integrator)."""
    a2, b2 = pdf_a * pdf_a, pdf_b * pdf_b
    w = a2 / (a2 + b2)
    return dr.select(dr.isfinite(w), w, 0.0)


def fluorescent_bsdfs(scene):
    """[(BSDFPtr, BSDF object)] of the scene's re-radiating BSDFs, each once."""
    found = {}
    for shape in scene.shapes():
        b = shape.bsdf()
        if b is not None and all(hasattr(b, m) for m in
                                 ("elastic_reflectance", "reradiation_albedo", "sample_excitation")):
            found[id(b)] = b
    return [(mi.BSDFPtr(b), b) for b in found.values()]


class FluorescentPathIntegrator(mi.SamplingIntegrator):
    def __init__(self, props):
        mi.SamplingIntegrator.__init__(self, props)
        if mi.is_polarized or not mi.is_spectral:
            raise RuntimeError(f"{PLUGIN_NAME} needs an unpolarised spectral variant (e.g. llvm_ad_spectral), "
                               f"not {mi.variant()}")
        max_depth = props.get("max_depth", -1)
        if max_depth < -1:
            raise ValueError(f"{PLUGIN_NAME}: max_depth must be >= -1, got {max_depth}")
        self.max_depth = 0xFFFFFFFF if max_depth == -1 else int(max_depth)
        self.rr_depth = int(props.get("rr_depth", 5))
        if self.rr_depth <= 0:
            raise ValueError(f"{PLUGIN_NAME}: rr_depth must be > 0, got {self.rr_depth}")

    def reradiate(self, fluorescent, bsdf, si, sampler, active):
        """Pick elastic or re-radiation per lane at fluorescent vertices. Returns (mask of
        fluorescent vertices, total albedo T(l_o) per lane, the lanes' new wavelengths)."""
        on_fluo = mi.Bool(False)
        total = dr.zeros(mi.UnpolarizedSpectrum)
        wavelengths = type(si.wavelengths)(si.wavelengths)
        for ptr, b in fluorescent:
            hit = active & (bsdf == ptr)
            rho = b.elastic_reflectance(si, hit)
            for k in range(len(wavelengths)):  # the lanes, one at a time (each has its own l_o)
                l_o = si.wavelengths[k]
                albedo = b.reradiation_albedo(l_o, hit)
                t = rho[k] + albedo
                target = sampler.next_1d(hit) * t - rho[k]
                shift = hit & (target >= 0) & (albedo > 0)
                l_i = b.sample_excitation(l_o, dr.minimum(target, albedo), shift)
                wavelengths[k] = dr.select(shift, l_i, wavelengths[k])
                total[k] = dr.select(hit, t, total[k])
            on_fluo |= hit
        return on_fluo, total, wavelengths

    @dr.syntax
    def sample(self, scene, sampler, ray, medium=None, active=True):
        fluorescent = fluorescent_bsdfs(scene)
        bsdf_ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray)  # a copy: the film reads the camera ray's wavelengths afterwards
        throughput = mi.Spectrum(1.0)
        result = mi.Spectrum(0.0)
        eta = mi.Float(1.0)
        depth = mi.UInt32(0)
        valid_ray = mi.Bool(scene.environment() is not None)
        prev_si = dr.zeros(mi.Interaction3f)
        prev_bsdf_pdf = mi.Float(1.0)
        prev_bsdf_delta = mi.Bool(True)
        active = mi.Bool(active)
        pi = scene.ray_intersect_preliminary(ray, coherent=True, active=active)

        while dr.hint(active, label=PLUGIN_NAME):
            si = pi.compute_surface_interaction(ray, mi.RayFlags.All)

            # ---------------- emission seen by the previous vertex's BSDF sample ----------------
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
            em_pdf = scene.pdf_emitter_direction(prev_si, ds, ~prev_bsdf_delta)
            mis_bsdf = mis_weight(prev_bsdf_pdf, dr.select(prev_bsdf_delta, 0.0, em_pdf))
            result = dr.fma(throughput, ds.emitter.eval(si, prev_bsdf_pdf > 0) * mis_bsdf, result)

            active_next = (depth + 1 < self.max_depth) & si.is_valid()
            bsdf = si.bsdf(ray)

            # ---------------- fluorescence: each lane chooses its wavelength -------------------
            on_fluo = mi.Bool(False)
            total = dr.zeros(mi.UnpolarizedSpectrum)
            if dr.hint(len(fluorescent) > 0, mode="scalar"):
                on_fluo, total, wavelengths = self.reradiate(fluorescent, bsdf, si, sampler, active_next)
                si.wavelengths = wavelengths

            # ---------------- emitter sampling ---------------------------------------------------
            active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
            active_em &= ds.pdf != 0.0
            wo = si.to_local(ds.d)

            sample_1 = sampler.next_1d()
            sample_2 = sampler.next_2d()
            bsdf_val, bsdf_pdf, bsdf_sample, bsdf_weight = bsdf.eval_pdf_sample(
                bsdf_ctx, si, wo, sample_1, sample_2, active_next)
            if dr.hint(len(fluorescent) > 0, mode="scalar"):
                # a fluorescent vertex is Lambertian with albedo T(l_o), light taken at l'
                bsdf_val = dr.select(on_fluo, total * bsdf_pdf, bsdf_val)
                bsdf_weight = dr.select(on_fluo & (bsdf_sample.pdf > 0), total,
                                        dr.select(on_fluo, 0.0, bsdf_weight))

            mis_em = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, bsdf_pdf))
            result[active_em] = dr.fma(throughput, bsdf_val * em_weight * mis_em, result)

            # ---------------- BSDF sampling -------------------------------------------------------
            ray = si.spawn_ray(si.to_world(bsdf_sample.wo))
            throughput *= bsdf_weight
            eta *= bsdf_sample.eta
            valid_ray |= active & si.is_valid() & ~mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Null)
            prev_si = mi.Interaction3f(si)
            prev_bsdf_pdf = bsdf_sample.pdf
            prev_bsdf_delta = mi.has_flag(bsdf_sample.sampled_type, mi.BSDFFlags.Delta)

            # ---------------- stopping criterion --------------------------------------------------
            depth[si.is_valid()] += 1
            throughput_max = dr.max(mi.unpolarized_spectrum(throughput))
            rr_prob = dr.minimum(throughput_max * dr.square(eta), 0.95)
            rr_active = depth >= self.rr_depth
            rr_continue = sampler.next_1d() < rr_prob
            throughput[rr_active] *= dr.rcp(rr_prob)
            active = active_next & (~rr_active | rr_continue) & (throughput_max != 0.0)
            pi = scene.ray_intersect_preliminary(ray, coherent=False, active=active)

        return dr.select(valid_ray, result, 0.0), valid_ray, []

    def aov_names(self):
        return []

    def to_string(self):
        return f"FluorescentPathIntegrator[max_depth={self.max_depth}, rr_depth={self.rr_depth}]"


def register():
    mi.register_integrator(PLUGIN_NAME, lambda props: FluorescentPathIntegrator(props))
