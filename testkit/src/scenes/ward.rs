//! The Ward-fit family: `family(Kind::WardFit, seed)` draws a weathered sample rendered with
//! Cook–Torrance (`weathering.sample`'s cross-model reflectance: Beckmann, Schlick's Fresnel,
//! V-cavity masking–shadowing, which a Ward lobe cannot reproduce) — its rust seeds, their
//! reach, the degree's roughness and the sample's seed — and writes the fit, the kNN graph and
//! the recovered weathering degree, each measured against the sample's own truth.

use super::SplitMix;
use serde_json::{json, Value};

/// The family's template, relative to the repository: seed 0's scene.
pub const TEMPLATE: &str = "graphs/family_ward_fit.json";

/// The sample's side in pixels.
pub const SIZE: u32 = 32;

/// One scene of the family.
#[derive(Clone, Debug)]
pub struct Scene {
    pub seed: u64,
    /// Points rust grows from, their reach (sample widths) and the degree's noise amplitude.
    pub seeds: u32,
    pub radius: f64,
    pub roughness: f64,
}

impl Scene {
    /// A one-line description naming the seed and every drawn parameter.
    pub fn name(&self) -> String {
        format!(
            "seed {}: {} rust seeds reaching {:.2}, degree roughness {:.2}",
            self.seed, self.seeds, self.radius, self.roughness
        )
    }

    /// The `--set`s that make [`TEMPLATE`] this scene.
    pub fn sets(&self) -> Vec<String> {
        let j = |v: Value| v.to_string();
        vec![
            format!("sample.seeds={}", self.seeds),
            format!("sample.radius={}", j(json!(self.radius))),
            format!("sample.roughness={}", j(json!(self.roughness))),
            format!("sample.seed={}", self.seed % 1_000_003 + 1),
        ]
    }

    /// The graph: the sample, `fit` (`brdf.fit_ward` with its errors against the true maps),
    /// `knn` and `degree` (`manifold.degree` with its Spearman correlation to the true degree).
    pub fn graph(&self) -> Value {
        json!({
            "mesoflow": 1,
            "description": format!("Scene family `ward_fit`, {}", self.name()),
            "nodes": {
                "sample": { "kind": "weathering.sample", "params": {
                    "size": SIZE, "seeds": self.seeds, "radius": self.radius,
                    "roughness": self.roughness, "reflectance": "cook_torrance",
                    "seed": self.seed % 1_000_003 + 1 } },
                "fit": {
                    "kind": "brdf.fit_ward",
                    "inputs": { "btf": "sample.btf", "truth": "sample.maps" },
                    "params": { "clusters": 8 }
                },
                "knn": { "kind": "manifold.knn", "inputs": { "points": "fit.appearance" }, "params": { "k": 10 } },
                "degree": {
                    "kind": "manifold.degree",
                    "inputs": {
                        "points": "fit.appearance",
                        "graph": "knn.graph",
                        "x0_mask": "sample.least",
                        "x1_mask": "sample.most",
                        "truth": "sample.degree"
                    }
                }
            }
        })
    }
}

/// The scene that `seed` draws.
pub fn draw(seed: u64) -> Scene {
    let mut r = SplitMix(seed ^ 0x3a4d_f17e_5eed_0001);
    Scene {
        seed,
        seeds: r.int(2, 8),
        radius: r.range(0.3, 0.5),
        roughness: r.range(0.2, 0.6),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_draws_the_same_scene_and_the_family_covers_its_ranges() {
        assert_eq!(draw(3).graph(), draw(3).graph());
        let scenes: Vec<Scene> = (0..100).map(draw).collect();
        assert!(scenes.iter().any(|s| s.seeds == 2) && scenes.iter().any(|s| s.seeds == 8));
        assert!(scenes
            .iter()
            .all(|s| (0.3..=0.5).contains(&s.radius) && (0.2..=0.6).contains(&s.roughness)));
    }
}
