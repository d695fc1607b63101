//! Subsurface scattering values: `ScatteringMaterial` (reduced scattering and absorption
//! coefficients per RGB channel in mm⁻¹, relative index of refraction η = n_inside / n_outside)
//! and `DiffusionProfile` (radial diffuse reflectance Rd(r) per channel on a radius grid, in
//! mm⁻², with its totals and a sampling table).

use mesoflow_runtime::codec::{DecodeError, Decoder, Encoder};
use mesoflow_runtime::{Value, ValueRef};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, PartialEq)]
pub struct ScatteringMaterial {
    /// σs′ = σs (1 − g), mm⁻¹.
    pub sigma_s_prime: [f64; 3],
    /// σa, mm⁻¹.
    pub sigma_a: [f64; 3],
    pub eta: f64,
    /// Henyey–Greenstein asymmetry of the phase function (σs = σs′/(1 − g)); only the Monte
    /// Carlo reference and single-scattering terms see it, diffusion depends on σs′ alone.
    pub g: f64,
}

impl ScatteringMaterial {
    pub const TYPE: &'static str = "ScatteringMaterial";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let mut v = [0.0; 8];
        for x in &mut v {
            *x = d.f64()?;
        }
        Ok(Arc::new(ScatteringMaterial {
            sigma_s_prime: [v[0], v[1], v[2]],
            sigma_a: [v[3], v[4], v[5]],
            eta: v[6],
            g: v[7],
        }))
    }
}

impl Value for ScatteringMaterial {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        64
    }
    fn encode(&self, out: &mut Encoder) {
        for x in self.sigma_s_prime.iter().chain(&self.sigma_a) {
            out.f64(*x);
        }
        out.f64(self.eta).f64(self.g);
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct DiffusionProfile {
    /// The model that produced it (`dipole`, …).
    pub model: String,
    /// Radii in mm, increasing, shared by the channels.
    pub radii: Vec<f64>,
    /// Rd(r) per channel, mm⁻².
    pub rd: [Vec<f64>; 3],
    /// Total diffuse reflectance ∫ Rd 2πr dr per channel (closed form where the model has one).
    pub total: [f64; 3],
    /// Effective mean free path 1/σtr per channel, mm (+∞ without absorption).
    pub mfp: [f64; 3],
    /// Normalised cumulative ∫₀^r Rd 2πr′ dr′ per channel at `radii`, for sampling radii.
    pub cdf: [Vec<f64>; 3],
}

impl DiffusionProfile {
    pub const TYPE: &'static str = "DiffusionProfile";

    pub fn decode(d: &mut Decoder) -> Result<ValueRef, DecodeError> {
        let model = d.str()?;
        let n = d.u64()? as usize;
        let read = |d: &mut Decoder| -> Result<Vec<f64>, DecodeError> {
            (0..n).map(|_| d.f64()).collect()
        };
        let radii = read(d)?;
        let rd = [read(d)?, read(d)?, read(d)?];
        let cdf = [read(d)?, read(d)?, read(d)?];
        let mut t = [0.0; 6];
        for x in &mut t {
            *x = d.f64()?;
        }
        Ok(Arc::new(DiffusionProfile {
            model,
            radii,
            rd,
            total: [t[0], t[1], t[2]],
            mfp: [t[3], t[4], t[5]],
            cdf,
        }))
    }
}

impl Value for DiffusionProfile {
    fn type_name(&self) -> &'static str {
        Self::TYPE
    }
    fn byte_size(&self) -> usize {
        self.radii.len() * 8 * 7
    }
    fn encode(&self, out: &mut Encoder) {
        out.str(&self.model).u64(self.radii.len() as u64);
        for v in std::iter::once(&self.radii)
            .chain(self.rd.iter())
            .chain(self.cdf.iter())
        {
            for x in v {
                out.f64(*x);
            }
        }
        for x in self.total.iter().chain(&self.mfp) {
            out.f64(*x);
        }
    }
    /// (4, n): radii in mm, then Rd for R, G, B in mm⁻² (the NPY contract).
    fn as_array_f64(&self) -> Option<(Vec<usize>, Vec<f64>)> {
        let n = self.radii.len();
        let mut data = Vec::with_capacity(4 * n);
        data.extend_from_slice(&self.radii);
        for c in &self.rd {
            data.extend_from_slice(c);
        }
        Some((vec![4, n], data))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}
