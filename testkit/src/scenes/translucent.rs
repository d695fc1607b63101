//! The translucent family: `family(Kind::Translucent, seed)` draws one scene (material, shape,
//! size, light, camera distance) from the seed alone and writes it as a graph: `sss.render` with
//! its defaults beside `render.reference`'s volumetric truth, compared.

use super::SplitMix;
use serde_json::{json, Value};

/// The translucent family's template, relative to the repository: seed 0's scene.
pub const TEMPLATE: &str = "graphs/family_translucent.json";

/// The template's resolution and samples a pixel (the bench's defaults).
pub const TEMPLATE_RESOLUTION: [u32; 2] = [64, 48];
pub const TEMPLATE_SAMPLES: u32 = 1024;

/// Jensen et al. 2001's measured materials (`sss.material`'s presets).
pub const PRESETS: [&str; 12] = [
    "apple",
    "chicken1",
    "chicken2",
    "cream",
    "ketchup",
    "marble",
    "potato",
    "skimmilk",
    "skin1",
    "skin2",
    "spectralon",
    "wholemilk",
];

/// Where the light comes from, seen from the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSide {
    Front,
    Side,
    Behind,
}

/// One scene of a family: everything that varies, drawn from the seed.
#[derive(Clone, Debug)]
pub struct Scene {
    pub seed: u64,
    pub preset: &'static str,
    /// `sphere` or `torus` (closed meshes: the truth fills them with the medium).
    pub shape: &'static str,
    /// `mesh.primitive`'s size and minor radius (world units).
    pub size: f64,
    pub minor: f64,
    /// Millimetres a world unit: with the material, how many mean free paths across.
    pub mm_per_unit: f64,
    pub light: LightSide,
    /// The camera's distance from the object's centre over its size.
    pub distance: f64,
}

impl Scene {
    /// A one-line description naming the seed and every drawn parameter.
    pub fn name(&self) -> String {
        format!(
            "seed {}: {} {} (size {:.2}{}) at {:.0} mm a unit, lit from the {}, camera at {:.1}×",
            self.seed,
            self.preset,
            self.shape,
            self.size,
            if self.shape == "torus" {
                format!(", tube {:.2}", self.minor)
            } else {
                String::new()
            },
            self.mm_per_unit,
            match self.light {
                LightSide::Front => "front",
                LightSide::Side => "side",
                LightSide::Behind => "behind",
            },
            self.distance
        )
    }

    /// The camera's eye and the direction towards the light, from the drawn parameters.
    pub fn view(&self) -> ([f64; 3], [f64; 3]) {
        let reach = self.size
            + if self.shape == "torus" {
                self.minor
            } else {
                0.0
            };
        let eye = [0.0, 0.35 * reach * self.distance, reach * self.distance];
        let direction = match self.light {
            // Towards the light (the camera looks along −z): over the camera's shoulder, from
            // the side, from behind the object (most of what is seen lit only through it).
            LightSide::Front => [0.3, 0.4, 1.0],
            LightSide::Side => [1.0, 0.3, 0.2],
            LightSide::Behind => [-0.3, 0.5, -1.0],
        };
        (eye, direction)
    }

    /// The truth's seed: its own per scene, so no two scenes share the truth's noise.
    fn truth_seed(&self) -> u64 {
        self.seed % 1_000_003 + 1
    }

    /// The `--set`s that make [`TEMPLATE`] this scene at `resolution` and `samples`: what the
    /// bench runs and what it prints, so a user can run any scene of the family with
    /// `mesoflow run graphs/family_translucent.json --set …`.
    pub fn sets(&self, resolution: [u32; 2], samples: u32) -> Vec<String> {
        let (eye, direction) = self.view();
        // serde_json's own text, so a float stays a float (`0.0`, not `0`) when read back.
        let j = |v: Value| v.to_string();
        let list = |v: [f64; 3]| j(json!(v));
        let mut sets = vec![
            format!("mesh.shape={}", self.shape),
            format!("mesh.size={}", j(json!(self.size))),
            format!("mesh.minor={}", j(json!(self.minor))),
            format!("material.preset={}", self.preset),
        ];
        // `ours` takes the light and the scale from its `lighting` (`sss.lighting`).
        for (view, lit) in [("ours", "lighting"), ("truth", "truth")] {
            sets.push(format!("{view}.camera.eye={}", list(eye)));
            sets.push(format!(
                "{view}.camera.resolution=[{},{}]",
                resolution[0], resolution[1]
            ));
            sets.push(format!("{lit}.light.direction={}", list(direction)));
            sets.push(format!("{lit}.mm_per_unit={}", j(json!(self.mm_per_unit))));
        }
        sets.push(format!("truth.samples={samples}"));
        sets.push(format!("truth.seed={}", self.truth_seed()));
        sets
    }

    /// The graph: `lighting` and `ours` (the method with its defaults, what does not depend on
    /// the camera in `sss.lighting`), `truth` (`render.reference` with the
    /// medium at `samples` a pixel), `error` (`image.compare` over the truth's coverage) and
    /// [`PICTURE`](super::PICTURE) (truth | ours | signed difference), at `resolution`. [`TEMPLATE`] is seed 0's at 64 × 48 and 1024 samples; [`Scene::sets`] turns
    /// it into any other (a test holds the two the same).
    pub fn graph(&self, resolution: [u32; 2], samples: u32) -> Value {
        let (eye, direction) = self.view();
        let camera =
            json!({ "eye": eye, "target": [0.0, 0.0, 0.0], "fov": 40.0, "resolution": resolution });
        let light = json!({ "direction": direction, "intensity": 5.0 });
        // `minor` is the torus's tube; a sphere ignores it (written so one template serves both).
        let mesh = json!({ "shape": self.shape, "size": self.size, "minor": self.minor, "segments": [96, 48] });
        let mut graph = json!({
            "mesoflow": 1,
            "description": format!("Scene family `translucent`, {}", self.name()),
            "nodes": {
                "mesh": { "kind": "mesh.primitive", "params": mesh },
                "material": { "kind": "sss.material", "params": { "preset": self.preset, "eta": 1.0 } },
                "profile": { "kind": "sss.profile", "inputs": { "material": "material.material" } },
                "lighting": {
                    "kind": "sss.lighting",
                    "inputs": { "mesh": "mesh.mesh", "material": "material.material", "profile": "profile.profile" },
                    "params": { "light": light, "mm_per_unit": self.mm_per_unit }
                },
                "ours": {
                    "kind": "sss.render",
                    "inputs": { "mesh": "mesh.mesh", "material": "material.material", "profile": "profile.profile", "lighting": "lighting.lighting" },
                    "params": { "camera": camera }
                },
                "truth": {
                    "kind": "render.reference",
                    "inputs": { "mesh": "mesh.mesh", "medium": "material.material" },
                    "params": { "camera": camera, "light": light, "mm_per_unit": self.mm_per_unit, "samples": samples, "seed": self.truth_seed() }
                },
                "error": {
                    "kind": "image.compare",
                    "inputs": { "reference": "truth.image", "image": "ours.image", "reference_mask": "truth.coverage" }
                }
            }
        });
        super::add_picture(&mut graph);
        graph
    }
}

/// The scene that `seed` draws.
pub fn draw(seed: u64) -> Scene {
    let mut r = SplitMix(seed ^ 0x5eed_fa31_1e5c_e7e5);
    let preset = PRESETS[r.below(PRESETS.len() as u64) as usize];
    let torus = r.below(2) == 1;
    let (shape, size, minor) = if torus {
        let size = r.range(0.6, 1.0);
        ("torus", size, size * r.range(0.3, 0.5))
    } else {
        ("sphere", r.range(0.5, 0.9), 0.0)
    };
    // 10 to 60 mm a unit: a few to hundreds of mean free paths across, thin scenes included.
    let mm_per_unit = (r.range(10f64.ln(), 60f64.ln())).exp();
    let light = [LightSide::Front, LightSide::Side, LightSide::Behind][r.below(3) as usize];
    let distance = r.range(2.4, 4.0);
    Scene {
        seed,
        preset,
        shape,
        size,
        minor,
        mm_per_unit,
        light,
        distance,
    }
}

/// The smallest thickness of a scene in reduced mean free paths (1/σt′ of the material's
/// thinnest channel), from the preset's coefficients (σs′ + σa per mm): the sphere's diameter,
/// the torus's tube. `coefficients` gives (σs′, σa) per channel for the preset.
pub fn mean_free_paths(scene: &Scene, coefficients: ([f64; 3], [f64; 3])) -> f64 {
    let across = if scene.shape == "torus" {
        2.0 * scene.minor
    } else {
        2.0 * scene.size
    } * scene.mm_per_unit;
    let (s, a) = coefficients;
    (0..3)
        .map(|c| across * (s[c] + a[c]))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_draws_the_same_scene_and_the_family_covers_its_ranges() {
        let a = draw(7);
        let b = draw(7);
        assert_eq!(a.name(), b.name());
        assert_eq!(a.graph([8, 6], 4), b.graph([8, 6], 4));
        let scenes: Vec<Scene> = (0..200).map(draw).collect();
        for p in PRESETS {
            assert!(scenes.iter().any(|s| s.preset == p), "{p}");
        }
        for l in [LightSide::Front, LightSide::Side, LightSide::Behind] {
            assert!(scenes.iter().any(|s| s.light == l), "{l:?}");
        }
        assert!(
            scenes.iter().any(|s| s.shape == "torus") && scenes.iter().any(|s| s.shape == "sphere")
        );
        assert!(scenes
            .iter()
            .all(|s| (10.0..=60.0).contains(&s.mm_per_unit) && (2.4..=4.0).contains(&s.distance)));
    }
}
