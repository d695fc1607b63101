//! `sss.material`: a homogeneous translucent material, from a preset of Jensen et al. 2001's
//! measured table (σs′, σa per RGB channel, mm⁻¹; η = 1.3) or from explicit coefficients.

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
    /// A measured material; or give `sigma_s_prime` and `sigma_a`.
    pub preset: Option<Preset>,
    /// Reduced scattering coefficient σs′ per channel, mm⁻¹.
    pub sigma_s_prime: Option<[f64; 3]>,
    /// Absorption coefficient σa per channel, mm⁻¹.
    pub sigma_a: Option<[f64; 3]>,
    /// Relative index of refraction n_inside / n_outside.
    #[schemars(range(min = 0.1, max = 10.0))]
    pub eta: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            preset: None,
            sigma_s_prime: None,
            sigma_a: None,
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
            version: 1,
            doc: "Homogeneous translucent material: a Jensen 2001 preset or σs′, σa (mm⁻¹, RGB) and η.",
            device: DevicePreference::Cpu,
            inputs: vec![],
            outputs: vec![Port::output("material", ScatteringMaterial::TYPE, "the coefficients")],
            disk_cache: false,
        }
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, _inputs: &Inputs) -> Result<Outputs, NodeError> {
        Ok(Outputs::new().with("material", material(p)?))
    }
}

pub fn material(p: &Params) -> Result<ScatteringMaterial, NodeError> {
    let (sigma_s_prime, sigma_a) = match (p.preset, p.sigma_s_prime, p.sigma_a) {
        (Some(preset), None, None) => preset.coefficients(),
        (None, Some(s), Some(a)) => (s, a),
        (Some(_), _, _) => {
            return Err(NodeError::param(
                "preset",
                "give a preset or sigma_s_prime and sigma_a, not both",
            ))
        }
        (None, None, _) => {
            return Err(NodeError::param(
                "sigma_s_prime",
                "missing: give a preset or sigma_s_prime and sigma_a",
            ))
        }
        (None, Some(_), None) => return Err(NodeError::param("sigma_a", "missing")),
    };
    for (name, v) in [("sigma_s_prime", sigma_s_prime), ("sigma_a", sigma_a)] {
        if let Some(x) = v.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
            return Err(NodeError::param(
                name,
                format!("{x} is not a finite, non-negative coefficient (mm⁻¹)"),
            ));
        }
    }
    if let Some(c) = (0..3).find(|&c| sigma_s_prime[c] + sigma_a[c] <= 0.0) {
        return Err(NodeError::param(
            "sigma_s_prime",
            format!("channel {c} neither scatters nor absorbs: the medium is empty"),
        ));
    }
    if !(p.eta.is_finite() && p.eta > 0.0) {
        return Err(NodeError::param(
            "eta",
            format!("{} is not a positive index ratio", p.eta),
        ));
    }
    Ok(ScatteringMaterial {
        sigma_s_prime,
        sigma_a,
        eta: p.eta,
    })
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
            "not both",
        );
    }
}
