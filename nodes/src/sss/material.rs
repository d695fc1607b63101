//! `sss.material`: a homogeneous translucent material, from a preset of Jensen et al. 2001's
//! measured table (σs′, σa per RGB channel, mm⁻¹; η = 1.3), from explicit coefficients (σs′, or
//! σs and g), or inversely from what an artist sees: the diffuse albedo (total diffuse
//! reflectance) and the mean free path 1/σt′ per channel, by inverting the chosen model's total
//! reflectance in the single-scattering albedo α′ (it depends on α′ and η only, and rises
//! monotonically with α′), as pbrt's `SubsurfaceFromDiffuse` does with a table.

use super::diffusion::Medium;
use super::dipole::Dipole;
use super::profile::{self, Model};
use crate::types::ScatteringMaterial;
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    Apple,
    Chicken1,
    Chicken2,
    Cream,
    Ketchup,
    Marble,
    Potato,
    Skimmilk,
    Skin1,
    Skin2,
    Spectralon,
    Wholemilk,
}

impl Preset {
    /// (σs′, σa), mm⁻¹, R G B: Jensen et al. 2001, Figure 5 (the domain notes' table; chicken2 and
    /// spectralon as pbrt-v3 lists them).
    pub fn coefficients(self) -> ([f64; 3], [f64; 3]) {
        match self {
            Preset::Apple => ([2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
            Preset::Chicken1 => ([0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
            Preset::Chicken2 => ([0.19, 0.25, 0.32], [0.018, 0.088, 0.20]),
            Preset::Cream => ([7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
            Preset::Ketchup => ([0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
            Preset::Marble => ([2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
            Preset::Potato => ([0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
            Preset::Skimmilk => ([0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
            Preset::Skin1 => ([0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
            Preset::Skin2 => ([1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
            Preset::Spectralon => ([11.6, 20.4, 14.9], [0.0, 0.0, 0.0]),
            Preset::Wholemilk => ([2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// A measured material; or give coefficients, or `albedo` and `mfp`.
    pub preset: Option<Preset>,
    /// Reduced scattering coefficient σs′ per channel, mm⁻¹.
    pub sigma_s_prime: Option<[f64; 3]>,
    /// Scattering coefficient σs per channel, mm⁻¹ (then σs′ = σs(1 − g)).
    pub sigma_s: Option<[f64; 3]>,
    /// Absorption coefficient σa per channel, mm⁻¹.
    pub sigma_a: Option<[f64; 3]>,
    /// Diffuse albedo (total diffuse reflectance) per channel, in [0, 1]; with `mfp`.
    pub albedo: Option<[f64; 3]>,
    /// Mean free path 1/σt′ per channel, mm; with `albedo`.
    pub mfp: Option<[f64; 3]>,
    /// The model whose total reflectance `albedo` is inverted with.
    pub inverse_model: Model,
    /// Henyey–Greenstein asymmetry of the phase function, in (−1, 1).
    #[schemars(range(min = -0.99, max = 0.99))]
    pub g: f64,
    /// Relative index of refraction n_inside / n_outside.
    #[schemars(range(min = 0.1, max = 10.0))]
    pub eta: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            preset: None,
            sigma_s_prime: None,
            sigma_s: None,
            sigma_a: None,
            albedo: None,
            mfp: None,
            inverse_model: Model::Dipole,
            g: 0.0,
            eta: 1.3,
        }
    }
}

pub struct Material;

impl Node for Material {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "sss.material",
            version: 2,
            doc: "Homogeneous translucent material: a Jensen 2001 preset, σs′ (or σs and g) and σa (mm⁻¹, RGB), or diffuse albedo and mean free path inverted through a model; and η.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("material", ScatteringMaterial::TYPE, "the coefficients")],
            disk_cache: false,
        }
    }

    /// The whole material is parameters: making it is the check (and cheap).
    fn check(&self, p: &Params) -> Result<(), NodeError> {
        material(p).map(drop)
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("material", material(p)?))
    }
}

pub fn material(p: &Params) -> Result<ScatteringMaterial, NodeError> {
    if !(p.g.is_finite() && p.g.abs() < 1.0) {
        return Err(NodeError::param("g", format!("{} is not in (−1, 1)", p.g)));
    }
    if !(p.eta.is_finite() && p.eta > 0.0) {
        return Err(NodeError::param(
            "eta",
            format!("{} is not a positive index ratio", p.eta),
        ));
    }
    let coefficients = p.sigma_s_prime.is_some() || p.sigma_s.is_some() || p.sigma_a.is_some();
    let inverse = p.albedo.is_some() || p.mfp.is_some();
    let (sigma_s_prime, sigma_a) = match (p.preset, coefficients, inverse) {
        (Some(preset), false, false) => preset.coefficients(),
        (None, true, false) => {
            let s = match (p.sigma_s_prime, p.sigma_s) {
                (Some(s), None) => s,
                (None, Some(s)) => {
                    check("sigma_s", s)?;
                    s.map(|v| v * (1.0 - p.g))
                }
                (Some(_), Some(_)) => {
                    return Err(NodeError::param(
                        "sigma_s",
                        "give sigma_s_prime or sigma_s (with g), not both",
                    ))
                }
                (None, None) => return Err(NodeError::param("sigma_s_prime", "missing")),
            };
            let a = p
                .sigma_a
                .ok_or_else(|| NodeError::param("sigma_a", "missing"))?;
            (s, a)
        }
        (None, false, true) => {
            let albedo = p
                .albedo
                .ok_or_else(|| NodeError::param("albedo", "missing: give it with mfp"))?;
            let mfp = p
                .mfp
                .ok_or_else(|| NodeError::param("mfp", "missing: give it with albedo"))?;
            invert(albedo, mfp, p)?
        }
        (None, false, false) => {
            return Err(NodeError::param(
                "sigma_s_prime",
                "missing: give a preset, sigma_s_prime and sigma_a, or albedo and mfp",
            ))
        }
        _ => {
            return Err(NodeError::param(
                "preset",
                "give one of: a preset, coefficients (sigma_s_prime or sigma_s, sigma_a), or albedo and mfp",
            ))
        }
    };
    check("sigma_s_prime", sigma_s_prime)?;
    check("sigma_a", sigma_a)?;
    if let Some(c) = (0..3).find(|&c| sigma_s_prime[c] + sigma_a[c] <= 0.0) {
        return Err(NodeError::param(
            "sigma_s_prime",
            format!("channel {c} neither scatters nor absorbs: the medium is empty"),
        ));
    }
    Ok(ScatteringMaterial {
        sigma_s_prime,
        sigma_a,
        eta: p.eta,
        g: p.g,
    })
}

fn check(name: &str, v: [f64; 3]) -> Result<(), NodeError> {
    match v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
        Some(x) => Err(NodeError::param(
            name,
            format!("{x} is not a finite, non-negative coefficient (mm⁻¹)"),
        )),
        None => Ok(()),
    }
}

/// Total diffuse reflectance of `model` at single-scattering albedo α′ (σt′ = 1: the total is
/// scale-free).
pub fn total_at(model: Model, alpha: f64, eta: f64, g: f64) -> f64 {
    match model {
        Model::Dipole => Dipole::new(alpha, 1.0 - alpha, eta).total(),
        _ => {
            let medium = Medium::new(alpha, 1.0 - alpha, g, eta);
            let rd = |r: f64| match model {
                Model::BetterDipole => medium.better_dipole(r),
                _ => medium.pbd(r),
            };
            profile::energy(&rd, 1.0).0
        }
    }
}

/// σs′, σa from the diffuse albedo and the mean free path 1/σt′, per channel, by bisection on
/// α′ (the total rises monotonically with α′; 50 halvings reach 1e-15).
fn invert(albedo: [f64; 3], mfp: [f64; 3], p: &Params) -> Result<([f64; 3], [f64; 3]), NodeError> {
    if p.inverse_model == Model::Montecarlo {
        return Err(NodeError::param(
            "inverse_model",
            "montecarlo has no deterministic total to invert: use dipole, better_dipole or pbd",
        ));
    }
    if let Some(x) = mfp.iter().find(|x| !(x.is_finite() && **x > 0.0)) {
        return Err(NodeError::param(
            "mfp",
            format!("{x} is not a positive length (mm)"),
        ));
    }
    let top = total_at(p.inverse_model, 1.0, p.eta, p.g);
    let mut s = [0.0; 3];
    let mut a = [0.0; 3];
    for c in 0..3 {
        let want = albedo[c];
        if !(want.is_finite() && (0.0..=top).contains(&want)) {
            return Err(NodeError::param(
                "albedo",
                format!(
                    "{want} is outside [0, {top:.4}], the totals {} reaches at η = {}",
                    p.inverse_model.name(),
                    p.eta
                ),
            ));
        }
        let (mut lo, mut hi) = (0.0, 1.0);
        for _ in 0..50 {
            let mid = 0.5 * (lo + hi);
            if total_at(p.inverse_model, mid, p.eta, p.g) < want {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let alpha = 0.5 * (lo + hi);
        s[c] = alpha / mfp[c];
        a[c] = (1.0 - alpha) / mfp[c];
    }
    Ok((s, a))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_and_explicit_coefficients_and_their_errors() {
        let m = material(&Params {
            preset: Some(Preset::Marble),
            ..Default::default()
        })
        .unwrap();
        assert_eq!(m.sigma_a, [0.0021, 0.0041, 0.0071]);
        let bad = |p: Params, word: &str| {
            let e = material(&p).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        };
        bad(Params::default(), "sigma_s_prime");
        bad(
            Params {
                sigma_s_prime: Some([1.0, -1.0, 1.0]),
                sigma_a: Some([0.1; 3]),
                ..Default::default()
            },
            "-1",
        );
        bad(
            Params {
                sigma_s_prime: Some([1.0, f64::NAN, 1.0]),
                sigma_a: Some([0.1; 3]),
                ..Default::default()
            },
            "NaN",
        );
        bad(
            Params {
                sigma_s_prime: Some([0.0; 3]),
                sigma_a: Some([0.0; 3]),
                ..Default::default()
            },
            "empty",
        );
        bad(
            Params {
                preset: Some(Preset::Apple),
                sigma_a: Some([0.1; 3]),
                ..Default::default()
            },
            "one of",
        );
    }

    #[test]
    fn albedo_and_mean_free_path_invert_to_the_coefficients() {
        // The domain notes' published curve: the dipole's total is 0.196903 at α′ = 0.8 and
        // 0.644525 at α′ = 0.99 (η = 1.3); with mfp = 1/σt′ = 2 mm that is σs′ = α′/2,
        // σa = (1 − α′)/2. The table has six digits: 1e-4 on α′ is ample.
        let m = material(&Params {
            albedo: Some([0.196903, 0.644525, 0.196903]),
            mfp: Some([2.0, 2.0, 0.5]),
            ..Default::default()
        })
        .unwrap();
        assert!((m.sigma_s_prime[0] - 0.4).abs() < 1e-4 && (m.sigma_a[0] - 0.1).abs() < 1e-4);
        assert!((m.sigma_s_prime[1] - 0.495).abs() < 1e-4);
        assert!((m.sigma_s_prime[2] - 1.6).abs() < 4e-4 && (m.sigma_a[2] - 0.4).abs() < 4e-4);
        // Through the improved models: the material's own profile has the asked total (the
        // profile integrates on its own grid: 2e-3).
        for model in [Model::BetterDipole, Model::Pbd] {
            let m = material(&Params {
                albedo: Some([0.3, 0.6, 0.9]),
                mfp: Some([1.0, 0.5, 3.0]),
                inverse_model: model,
                ..Default::default()
            })
            .unwrap();
            let prof = profile::tabulate(
                &m,
                &profile::Params {
                    model,
                    ..Default::default()
                },
                &crate::support::progress::Counter::none(),
            )
            .profile;
            for (c, want) in [0.3, 0.6, 0.9].iter().enumerate() {
                assert!(
                    (prof.total[c] - want).abs() < 2e-3,
                    "{model:?} {c}: {}",
                    prof.total[c]
                );
            }
        }
        let bad = |p: Params, word: &str| {
            let e = material(&p).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        };
        bad(
            Params {
                albedo: Some([1.2, 0.5, 0.5]),
                mfp: Some([1.0; 3]),
                ..Default::default()
            },
            "albedo",
        );
        bad(
            Params {
                albedo: Some([0.5; 3]),
                mfp: Some([0.0, 1.0, 1.0]),
                ..Default::default()
            },
            "mfp",
        );
        bad(
            Params {
                albedo: Some([0.5; 3]),
                ..Default::default()
            },
            "mfp",
        );
        bad(
            Params {
                albedo: Some([0.5; 3]),
                mfp: Some([1.0; 3]),
                sigma_a: Some([0.1; 3]),
                ..Default::default()
            },
            "one of",
        );
        // σs with g: σs′ = σs(1 − g).
        let m = material(&Params {
            sigma_s: Some([10.0; 3]),
            sigma_a: Some([0.1; 3]),
            g: 0.9,
            ..Default::default()
        })
        .unwrap();
        assert!((m.sigma_s_prime[0] - 1.0).abs() < 1e-12 && m.g == 0.9);
        bad(
            Params {
                sigma_s: Some([10.0; 3]),
                sigma_a: Some([0.1; 3]),
                g: 1.0,
                ..Default::default()
            },
            "g",
        );
    }
}
