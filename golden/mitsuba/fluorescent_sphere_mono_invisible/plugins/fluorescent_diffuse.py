"""sb_fluorescent_diffuse: a Lambertian surface that also re-radiates light at longer wavelengths
(Mitsuba 3 Python BSDF of spectral_bench; standalone: imports mitsuba, drjit and numpy only).

    <bsdf type="sb_fluorescent_diffuse">
        <spectrum name="reflectance" filename="spectra/x_reflectance.spd"/>   elastic part rho
        <string name="reradiation" value="fluorescence/x.txt"/>               table of P (1/nm)
    </bsdf>

The scattered radiance is L_o(l_o) = rho(l_o) L_i(l_o) + integral P(l_i, l_o) L_i(l_i) dl_i
per direction over the cosine-weighted hemisphere (the scene IR's definition, written down in
spectral_bench's exporters/fluorescence.py, which also writes the table). A BSDF cannot change a
ray's wavelength, so as a BSDF this plugin is only the elastic part rho: integrators other than
sb_fluorescent_path render the surface without its fluorescence. sb_fluorescent_path finds the
surfaces that carry ``reradiation_albedo`` / ``sample_excitation`` (this class) and re-radiates.

The table file: comment lines (#), then ``excitation <first nm> <step nm> <rows>``,
``emission <first nm> <step nm> <columns>`` and the rows of P; cells are ``step`` nm wide and
centred on their wavelengths, P is constant over a cell and 0 outside the block. For each
emission cell the BSDF keeps the cumulative sum over excitation cells of P * step (its last
entry is the re-radiation albedo A(l_o) = integral P(l_i, l_o) dl_i), so an excitation wavelength
is drawn in proportion to P(., l_o) by a binary search and inversion inside the cell.
"""
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

PLUGIN_NAME = "sb_fluorescent_diffuse"


def read_table(path):
    """(excitation first, step, emission first, step, P[rows, columns]) from a table file."""
    header, rows = {}, []
    for line in Path(path).read_text().splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        key = line.split()[0]
        if key in ("excitation", "emission"):
            _, first, step, count = line.split()
            header[key] = (float(first), float(step), int(count))
        else:
            rows.append([float(v) for v in line.split()])
    (ex0, exs, n_ex), (em0, ems, n_em) = header["excitation"], header["emission"]
    m = np.asarray(rows, dtype=np.float64).reshape(n_ex, n_em)
    if n_ex and n_em and (exs != ems or exs <= 0):
        raise ValueError(f"{path}: excitation and emission cells must have one positive width")
    if (m < 0).any() or not np.isfinite(m).all():
        raise ValueError(f"{path}: re-radiation must be finite and >= 0")
    return ex0, exs, em0, ems, m


class FluorescentDiffuse(mi.BSDF):
    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        if mi.is_polarized or not mi.is_spectral:
            raise RuntimeError(f"{PLUGIN_NAME} needs an unpolarised spectral variant (e.g. llvm_ad_spectral), "
                               f"not {mi.variant()}")
        if "reflectance" not in props:
            raise ValueError(f"{PLUGIN_NAME}: give the elastic reflectance as <spectrum name=\"reflectance\" .../>")
        self.reflectance = props.get_texture("reflectance")
        name = props.get("reradiation", "")
        if not name:
            raise ValueError(f"{PLUGIN_NAME}: give the re-radiation table as <string name=\"reradiation\" .../>")
        path = str(mi.Thread.thread().file_resolver().resolve(name))
        self.table_path = path
        ex0, step, em0, _, m = read_table(path)
        self.n_ex, self.n_em = m.shape
        self.step = step if m.size else 1.0
        self.ex_lo = ex0 - 0.5 * self.step  # left edge of the first excitation cell
        self.em_lo = em0 - 0.5 * self.step
        cdf = np.zeros((self.n_em, self.n_ex + 1))
        cdf[:, 1:] = np.cumsum(m.T * self.step, axis=1)
        self.albedo_max = float(cdf[:, -1].max()) if m.size else 0.0
        self.cdf = mi.Float(cdf.reshape(-1).astype(np.float32)) if m.size else mi.Float(0.0)
        flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_flags = flags
        self.m_components = [flags]

    # --- the elastic part, as a BSDF (Mitsuba's diffuse plugin) --------------------------------
    def sample(self, ctx, si, sample1, sample2, active=True):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        bs = dr.zeros(mi.BSDFSample3f)
        active = active & (cos_i > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
        bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
        bs.pdf = dr.select(active, mi.warp.square_to_cosine_hemisphere_pdf(bs.wo), 0.0)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        bs.sampled_component = mi.UInt32(0)
        value = self.reflectance.eval(si, active)
        return bs, dr.select(active & (bs.pdf > 0), value, 0.0)

    def eval(self, ctx, si, wo, active=True):
        cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
        return dr.select(active, self.reflectance.eval(si, active) * dr.inv_pi * cos_o, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        cos_i, cos_o = mi.Frame3f.cos_theta(si.wi), mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0) & ctx.is_enabled(mi.BSDFFlags.DiffuseReflection)
        return dr.select(active, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def eval_diffuse_reflectance(self, si, active=True):
        return self.reflectance.eval(si, active)

    # --- the re-radiation, for sb_fluorescent_path ----------------------------------------------
    def elastic_reflectance(self, si, active):
        """rho at si.wavelengths (all lanes)."""
        return self.reflectance.eval(si, active)

    def _column(self, wavelength, active):
        o = mi.Int32(dr.floor((wavelength - self.em_lo) / self.step))
        ok = active & (o >= 0) & (o < self.n_em)
        return mi.UInt32(dr.select(ok, o, 0)) * (self.n_ex + 1), ok

    def reradiation_albedo(self, wavelength, active):
        """A(l_o) = integral P(l_i, l_o) dl_i for one lane of emission wavelengths (Float)."""
        if self.n_ex == 0 or self.n_em == 0:
            return mi.Float(0.0)
        base, ok = self._column(wavelength, active)
        return dr.gather(mi.Float, self.cdf, base + self.n_ex, ok)

    def sample_excitation(self, wavelength, target, active):
        """The excitation wavelength l_i whose cumulative re-radiation into ``wavelength`` reaches
        ``target`` (uniform in [0, A(l_o))): l_i has density P(l_i, l_o) / A(l_o)."""
        if self.n_ex == 0 or self.n_em == 0:
            return mi.Float(wavelength)
        base, ok = self._column(wavelength, active)
        k = mi.math.find_interval(self.n_ex + 1,
                                  lambda idx: dr.gather(mi.Float, self.cdf, base + idx, ok) <= target)
        c0 = dr.gather(mi.Float, self.cdf, base + k, ok)
        c1 = dr.gather(mi.Float, self.cdf, base + k + 1, ok)
        t = dr.clip(dr.select(c1 > c0, (target - c0) / (c1 - c0), 0.5), 0.0, 1.0)
        return dr.select(ok, self.ex_lo + (mi.Float(k) + t) * self.step, wavelength)

    def traverse(self, callback):
        callback.put("reflectance", self.reflectance, mi.ParamFlags.Differentiable)

    def to_string(self):
        return (f"FluorescentDiffuse[reflectance={self.reflectance}, reradiation={self.table_path!r}, "
                f"max re-radiation albedo={self.albedo_max:.4g}]")


def register():
    mi.register_bsdf(PLUGIN_NAME, lambda props: FluorescentDiffuse(props))
