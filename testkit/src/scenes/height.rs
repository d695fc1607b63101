//! The height-from-normals family: `family(Kind::HeightFromNormals, seed)` draws a tile (the
//! mesostructure family's reliefs: bumps, weave, cells, fBm noise, the three photographs; 2–10
//! texels deep on 64²) and a corruption of its normals (Gaussian tilts of 0–4°, 0, 5 or 10%
//! outliers at 20–40°), and writes `graphs/height_from_normals.json`'s three integrations of
//! the corrupted normals (plain least squares, least squares weighted by each normal's
//! residual, Frankot–Chellappa) with their height errors against the tile.

use super::mesostructure::Relief;
use super::SplitMix;
use serde_json::{json, Value};

/// The family's template, relative to the repository: seed 0's scene.
pub const TEMPLATE: &str = "graphs/family_height_from_normals.json";

/// The tile's side in texels.
pub const TILE: u32 = 64;

/// One scene of the family.
#[derive(Clone, Debug)]
pub struct Scene {
    pub seed: u64,
    pub relief: Relief,
    /// The tallest feature, texels.
    pub depth: f64,
    /// The normals' Gaussian tilt along each tangent axis, degrees.
    pub sigma_deg: f64,
    /// The share of outliers and their tilt, degrees.
    pub outliers: f64,
    pub outlier_deg: f64,
}

impl Scene {
    /// A one-line description naming the seed and every drawn parameter.
    pub fn name(&self) -> String {
        format!(
            "seed {}: {}, {:.1} texels deep, tilts σ {:.1}°, {:.0}% outliers at {:.0}°",
            self.seed,
            self.relief.describe(),
            self.depth,
            self.sigma_deg,
            100.0 * self.outliers,
            self.outlier_deg
        )
    }

    /// The `--set`s that make [`TEMPLATE`] this scene.
    pub fn sets(&self) -> Vec<String> {
        let j = |v: Value| v.to_string();
        let mut sets = self.relief.sets(self.depth, self.seed);
        sets.extend([
            format!("noise.sigma_deg={}", j(json!(self.sigma_deg))),
            format!("noise.outliers={}", j(json!(self.outliers))),
            format!("noise.outlier_deg={}", j(json!(self.outlier_deg))),
            format!("noise.seed={}", self.seed % 1_000_003 + 1),
        ]);
        sets
    }

    /// The graph: the tile, its normals, their corruption (`noise`) and the three integrations
    /// (`plain`, `weighted`, `fourier`), each with `error_texels` against the tile; and `clean`,
    /// the uncorrupted normals integrated (what the tile's own relief costs: normals cannot say
    /// how tall a cliff is).
    pub fn graph(&self) -> Value {
        let integrate = |method: &str, weighted: bool| {
            let mut n = json!({
                "kind": "heightfield.from_normals",
                "inputs": { "normals": "noise.normals", "truth": "surface.height" },
                "params": { "method": method }
            });
            if weighted {
                n["inputs"]["weight"] = json!("noise.error_deg");
                n["params"]["weight_is"] = json!("residual");
            }
            n
        };
        let mut graph = json!({
            "mesoflow": 1,
            "description": format!("Scene family `height_from_normals`, {}", self.name()),
            "nodes": {
                "normals": { "kind": "heightfield.normals", "inputs": { "height": "surface.height" } },
                "noise": {
                    "kind": "heightfield.normal_noise",
                    "inputs": { "normals": "normals.normals" },
                    "params": { "sigma_deg": self.sigma_deg, "outliers": self.outliers,
                                "outlier_deg": self.outlier_deg, "seed": self.seed % 1_000_003 + 1 }
                },
                "clean": {
                    "kind": "heightfield.from_normals",
                    "inputs": { "normals": "normals.normals", "truth": "surface.height" },
                    "params": { "method": "least_squares" }
                },
                "plain": integrate("least_squares", false),
                "weighted": integrate("least_squares", true),
                "fourier": integrate("fourier", false)
            }
        });
        super::prepend(&mut graph, self.relief.nodes(self.depth, self.seed));
        graph
    }
}

/// The scene that `seed` draws.
pub fn draw(seed: u64) -> Scene {
    let mut r = SplitMix(seed ^ 0x4e16_4700_f50a_11e5);
    let relief = super::mesostructure::draw_relief(&mut r);
    let depth = r.range(2.0, 10.0);
    let sigma_deg = r.range(0.0, 4.0);
    let outliers = [0.0, 0.05, 0.1][r.below(3) as usize];
    let outlier_deg = r.range(20.0, 40.0);
    Scene {
        seed,
        relief,
        depth,
        sigma_deg,
        outliers,
        outlier_deg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_draws_the_same_scene_and_the_family_covers_its_ranges() {
        assert_eq!(draw(3).graph(), draw(3).graph());
        let scenes: Vec<Scene> = (0..200).map(draw).collect();
        for o in [0.0, 0.05, 0.1] {
            assert!(scenes.iter().any(|s| s.outliers == o), "{o}");
        }
        assert!(scenes
            .iter()
            .all(|s| (0.0..=4.0).contains(&s.sigma_deg) && (2.0..=10.0).contains(&s.depth)));
        assert!(scenes.iter().any(|s| matches!(s.relief, Relief::Photo(_))));
    }
}
