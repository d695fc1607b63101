//! The mesostructure family: `family(Kind::Mesostructure, seed)` draws one scene (height field,
//! reflectance, mesh and tiling, light, camera) from the seed alone and writes it as a graph:
//! `render.mesh` with its defaults (a BTF captured from the height field at UBO2003's 81 × 81
//! directions, the MDF of the same tile) beside `render.reference` on the true geometry
//! (`mesh.displace` of the same tile: exact geometry, exact hard shadows, the same reflectance,
//! camera and light), compared over the pixels either shows the object in.
//!
//! Height fields: bumps (2–16 a tile), weave, cells, fBm noise, and three photographs as heights
//! (scikit-image's gravel, brick and grass, `graphs/data/make_photo_heights.py`), 2–10 texels
//! deep on a 64² tile. Reflectance: Lambert, Ward or GGX. Meshes: tori of several radii,
//! spheres, open cylinders and a plane with open edges, each tiled so a tile is about square.
//! Light from the front, the side, grazing or from behind; the camera at several distances.

use super::SplitMix;
use serde_json::{json, Value};

/// The family's template, relative to the repository: seed 0's scene.
pub const TEMPLATE: &str = "graphs/family_mesostructure.json";

/// The template's resolution and the truth's samples a pixel (the bench's defaults).
pub const TEMPLATE_RESOLUTION: [u32; 2] = [320, 240];
/// 64 a pixel: at 16 the truths' own noise estimate reached 0.31 (a sphere's rim lit from
/// behind), over a third of the 0.30 bound.
pub const TEMPLATE_SAMPLES: u32 = 64;

/// The height field tile's side in texels.
pub const TILE: u32 = 64;

/// The photographs the family takes heights from (relative to `graphs/`).
pub const PHOTOS: [&str; 3] = ["data/gravel.png", "data/brick.png", "data/grass.png"];

/// The mesostructure: a procedural pattern or a photograph's brightness.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Relief {
    /// `heightfield.procedural` with this pattern, feature count and width.
    Pattern {
        pattern: &'static str,
        count: u32,
        width: f64,
    },
    /// One of [`PHOTOS`].
    Photo(&'static str),
}

impl Relief {
    /// A short description: the pattern with its count and width, or the photograph.
    pub fn describe(&self) -> String {
        match *self {
            Relief::Pattern {
                pattern,
                count,
                width,
            } => format!("{pattern} ×{count} (width {width:.2})"),
            Relief::Photo(p) => format!(
                "photo {}",
                p.trim_start_matches("data/").trim_end_matches(".png")
            ),
        }
    }

    /// The procedural node's parameters (drawn for a photograph's scene too, where its output
    /// only gives the tile's size).
    fn pattern(&self) -> (&'static str, u32, f64) {
        match *self {
            Relief::Pattern {
                pattern,
                count,
                width,
            } => (pattern, count, width),
            Relief::Photo(_) => ("bumps", 8, 0.8),
        }
    }

    /// `heightfield.edit`'s operation and amount: the pattern as it is, or the photograph
    /// (heights 0 to 1) scaled to `depth`.
    fn edit(&self, depth: f64) -> (&'static str, f64) {
        match self {
            Relief::Pattern { .. } => ("scale", 1.0),
            Relief::Photo(_) => ("replace", depth),
        }
    }

    fn photo(&self) -> &'static str {
        match *self {
            Relief::Photo(p) => p,
            Relief::Pattern { .. } => PHOTOS[0],
        }
    }

    /// The three nodes that make the tile, `depth` texels deep: `pattern`
    /// (`heightfield.procedural`), `photo` (`heightfield.read`) and `surface`
    /// (`heightfield.edit`: the pattern as it is, or the photograph in its place).
    pub(crate) fn nodes(&self, depth: f64, seed: u64) -> [(&'static str, Value); 3] {
        let (pattern, count, width) = self.pattern();
        let (operation, amount) = self.edit(depth);
        [
            (
                "pattern",
                json!({ "kind": "heightfield.procedural", "params": {
                    "pattern": pattern, "size": TILE, "count": count, "width": width,
                    "depth": depth, "seed": seed } }),
            ),
            (
                "photo",
                json!({ "kind": "heightfield.read", "params": { "path": self.photo(), "depth": 1.0 } }),
            ),
            (
                "surface",
                json!({
                    "kind": "heightfield.edit",
                    "inputs": { "height": "pattern.height", "other": "photo.height" },
                    "params": { "operation": operation, "amount": amount }
                }),
            ),
        ]
    }

    /// The `--set`s that make [`Relief::nodes`] this relief.
    pub(crate) fn sets(&self, depth: f64, seed: u64) -> Vec<String> {
        let j = |v: Value| v.to_string();
        let (pattern, count, width) = self.pattern();
        let (operation, amount) = self.edit(depth);
        vec![
            format!("pattern.pattern={pattern}"),
            format!("pattern.count={count}"),
            format!("pattern.width={}", j(json!(width))),
            format!("pattern.depth={}", j(json!(depth))),
            format!("pattern.seed={seed}"),
            format!("photo.path={}", self.photo()),
            format!("surface.operation={operation}"),
            format!("surface.amount={}", j(json!(amount))),
        ]
    }
}

/// Where the light comes from, seen from the camera.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSide {
    Front,
    Side,
    /// Nearly tangent to the surface the camera sees most of.
    Grazing,
    Behind,
}

/// One scene of the family: everything that varies, drawn from the seed.
#[derive(Clone, Debug)]
pub struct Scene {
    pub seed: u64,
    pub relief: Relief,
    /// The tallest feature, texels.
    pub depth: f64,
    /// `lambert`, `ward` or `ggx`, with its diffuse albedo, lobe weight and roughness.
    pub brdf: &'static str,
    pub albedo: [f64; 3],
    pub specular: f64,
    pub roughness: f64,
    /// `torus`, `sphere`, `cylinder` (open) or `plane` (open edges).
    pub shape: &'static str,
    /// `mesh.primitive`'s size and minor (torus tube, cylinder height).
    pub size: f64,
    pub minor: f64,
    /// Tiles along u and v.
    pub tiling: [u32; 2],
    pub light: LightSide,
    /// The direction towards the light.
    pub direction: [f64; 3],
    /// The camera's position.
    pub eye: [f64; 3],
}

impl Scene {
    /// Whether the mesh is closed (a silhouette's IoU is held on these).
    pub fn closed(&self) -> bool {
        matches!(self.shape, "torus" | "sphere")
    }

    /// A one-line description naming the seed and every drawn parameter.
    pub fn name(&self) -> String {
        let relief = self.relief.describe();
        let brdf = match self.brdf {
            "lambert" => "Lambert".to_string(),
            b => format!("{b} (ρs {:.2}, α {:.2})", self.specular, self.roughness),
        };
        let shape = match self.shape {
            "torus" => format!("torus {:.2}/{:.2}", self.size, self.minor),
            "cylinder" => format!("open cylinder r {:.2} h {:.2}", self.size, self.minor),
            "plane" => format!("plane {:.1}", self.size),
            s => format!("{s} {:.2}", self.size),
        };
        let d = self.eye.iter().map(|v| v * v).sum::<f64>().sqrt();
        format!(
            "seed {}: {relief}, {:.1} texels deep, {brdf}, {shape}, {}×{} tiles, {}, camera at {d:.1}",
            self.seed,
            self.depth,
            self.tiling[0],
            self.tiling[1],
            match self.light {
                LightSide::Front => "lit from the front",
                LightSide::Side => "lit from the side",
                LightSide::Grazing => "grazing light",
                LightSide::Behind => "lit from behind",
            },
        )
    }

    /// The world size of a texel along u (at the mesh's widest u circle): the shell is the
    /// tile's depth in texels at that scale, so a texel's height and width are about equal.
    fn texel(&self) -> f64 {
        let around = match self.shape {
            "plane" => self.size,
            _ => std::f64::consts::TAU * self.size,
        };
        around / self.tiling[0] as f64 / TILE as f64
    }

    /// The shell: `depth` texels at the tile's texel size. `mdf.tabulate` and `mesh.displace`
    /// are given the same `depth` (their default, the tile's height range, is less than the
    /// drawn depth for noise and cells, which would stretch the truth's relief against the
    /// captured one: the family's first run had it so).
    fn shell(&self) -> f64 {
        self.shell_depth() * self.texel()
    }

    /// The shell's depth in texels: the drawn depth and a millionth, so the f32 tile's range
    /// (the drawn depth rounded, up as often as down) fits inside it.
    fn shell_depth(&self) -> f64 {
        self.depth * (1.0 + 1e-6)
    }

    fn segments(&self) -> [u32; 2] {
        if self.shape == "plane" {
            [16, 16]
        } else {
            [96, 48]
        }
    }

    fn tiling_f(&self) -> [f64; 2] {
        [self.tiling[0] as f64, self.tiling[1] as f64]
    }

    /// The `--set`s that make [`TEMPLATE`] this scene at `resolution` and `samples`.
    pub fn sets(&self, resolution: [u32; 2], samples: u32) -> Vec<String> {
        // serde_json's own text, so a float stays a float (`0.0`, not `0`) when read back.
        let j = |v: Value| v.to_string();
        let mut sets = self.relief.sets(self.depth, self.seed);
        sets.extend([
            format!("mesh.shape={}", self.shape),
            format!("mesh.size={}", j(json!(self.size))),
            format!("mesh.minor={}", j(json!(self.minor))),
            format!("mesh.segments={}", j(json!(self.segments()))),
            format!("mdf.depth={}", j(json!(self.shell_depth()))),
            format!("true_surface.tiling={}", j(json!(self.tiling_f()))),
            format!("true_surface.shell={}", j(json!(self.shell()))),
            format!("true_surface.depth={}", j(json!(self.shell_depth()))),
            format!("ours.tiling={}", j(json!(self.tiling_f()))),
            format!("ours.shell={}", j(json!(self.shell()))),
        ]);
        for id in ["capture", "truth"] {
            sets.push(format!("{id}.brdf={}", self.brdf));
            sets.push(format!("{id}.albedo={}", j(json!(self.albedo))));
            sets.push(format!("{id}.specular={}", j(json!(self.specular))));
            sets.push(format!("{id}.roughness={}", j(json!(self.roughness))));
        }
        for id in ["ours", "truth"] {
            sets.push(format!("{id}.camera.eye={}", j(json!(self.eye))));
            sets.push(format!(
                "{id}.camera.resolution=[{},{}]",
                resolution[0], resolution[1]
            ));
            sets.push(format!("{id}.light.direction={}", j(json!(self.direction))));
        }
        sets.push(format!("truth.samples={samples}"));
        sets.push(format!("truth.seed={}", self.truth_seed()));
        sets
    }

    /// The truth's seed: its own per scene.
    fn truth_seed(&self) -> u64 {
        self.seed % 1_000_003 + 1
    }

    /// The graph: `ours` (`render.mesh` with its defaults but the scene's camera, light, tiling
    /// and shell), `truth` (`render.reference` on `true_surface` at `samples` a pixel),
    /// `error` (`image.compare` over both masks), `flip` and [`PICTURE`](super::PICTURE). [`TEMPLATE`] is seed
    /// 0's at [`TEMPLATE_RESOLUTION`] and [`TEMPLATE_SAMPLES`]; [`Scene::sets`] turns it into any
    /// other (a test holds the two the same).
    pub fn graph(&self, resolution: [u32; 2], samples: u32) -> Value {
        let camera = json!({ "eye": self.eye, "target": [0.0, 0.0, 0.0], "fov": 40.0, "resolution": resolution });
        let light = json!({ "direction": self.direction, "intensity": 3.0 });
        let reflectance = |mut v: Value| {
            v["brdf"] = json!(self.brdf);
            v["albedo"] = json!(self.albedo);
            v["specular"] = json!(self.specular);
            v["roughness"] = json!(self.roughness);
            v
        };
        let mut graph = json!({
            "mesoflow": 1,
            "description": format!("Scene family `mesostructure`, {}", self.name()),
            "nodes": {
                "capture": {
                    "kind": "btf.capture",
                    "inputs": { "height": "surface.height" },
                    "params": reflectance(json!({ "views": "ubo81", "lights": "ubo81", "samples": 2 }))
                },
                "mdf": {
                    "kind": "mdf.tabulate",
                    "inputs": { "height": "surface.height" },
                    "params": { "depth": self.shell_depth(), "views": { "thetas": [0, 15, 30, 45, 60, 70, 80, 85, 88, 89.5], "phis": [0, 15, 30, 45, 60, 75, 90, 105, 120, 135, 150, 165, 180, 195, 210, 225, 240, 255, 270, 285, 300, 315, 330, 345] } }
                },
                "mesh": { "kind": "mesh.primitive", "params": {
                    "shape": self.shape, "size": self.size, "minor": self.minor, "segments": self.segments() } },
                "true_surface": {
                    "kind": "mesh.displace",
                    "inputs": { "mesh": "mesh.mesh", "height": "surface.height" },
                    "params": { "tiling": self.tiling_f(), "shell": self.shell(), "depth": self.shell_depth(), "density": 2.0 }
                },
                "truth": {
                    "kind": "render.reference",
                    "inputs": { "mesh": "true_surface.mesh" },
                    "params": reflectance(json!({ "camera": camera, "light": light, "samples": samples, "seed": self.truth_seed() }))
                },
                "ours": {
                    "kind": "render.mesh",
                    "inputs": { "mesh": "mesh.mesh", "btf": "capture.btf", "mdf": "mdf.mdf" },
                    "params": { "camera": camera, "light": light, "tiling": self.tiling_f(), "shell": self.shell() }
                },
                "error": {
                    "kind": "image.compare",
                    "inputs": { "reference": "truth.image", "image": "ours.image", "reference_mask": "truth.coverage", "mask": "ours.mask" }
                },
                "flip": {
                    "kind": "image.flip",
                    "inputs": { "reference": "truth.image", "test": "ours.image" },
                    "params": { "object_only": true }
                }
            }
        });
        super::prepend(&mut graph, self.relief.nodes(self.depth, self.seed));
        super::add_picture(&mut graph);
        graph
    }
}

/// `v` turned by `degrees` about the y axis.
fn yaw(v: [f64; 3], degrees: f64) -> [f64; 3] {
    let (s, c) = degrees.to_radians().sin_cos();
    [c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]]
}

/// A relief drawn from `r`: bumps (2–16 a tile, a quarter of the family), a weave, cells, fBm
/// noise (an eighth each) or one of the photographs (three eighths).
pub(crate) fn draw_relief(r: &mut SplitMix) -> Relief {
    match r.below(8) {
        0 | 1 => Relief::Pattern {
            pattern: "bumps",
            count: r.int(2, 16),
            width: r.range(0.5, 0.95),
        },
        2 => Relief::Pattern {
            pattern: "weave",
            count: 2 * r.int(2, 6),
            width: r.range(0.6, 0.9),
        },
        3 => Relief::Pattern {
            pattern: "cells",
            count: r.int(3, 10),
            width: r.range(0.1, 0.3),
        },
        4 => Relief::Pattern {
            pattern: "noise",
            count: r.int(2, 6),
            width: 0.8,
        },
        _ => Relief::Photo(PHOTOS[r.below(PHOTOS.len() as u64) as usize]),
    }
}

/// The scene that `seed` draws.
pub fn draw(seed: u64) -> Scene {
    let mut r = SplitMix(seed ^ 0x3e50_f10e_a11c_e5ed);
    let relief = draw_relief(&mut r);
    let depth = r.range(2.0, 10.0);
    let brdf = ["lambert", "ward", "ggx"][r.below(3) as usize];
    let albedo = [r.range(0.3, 0.8), r.range(0.3, 0.8), r.range(0.3, 0.8)];
    let (specular, roughness) = match brdf {
        "ward" => (r.range(0.03, 0.2), r.range(0.1, 0.35)),
        "ggx" => (1.0, r.range(0.15, 0.4)),
        _ => (0.05, 0.2),
    };
    let shape = ["torus", "torus", "sphere", "cylinder", "plane"][r.below(5) as usize];
    let (size, minor, tiling) = match shape {
        "torus" => {
            let size = r.range(0.6, 1.0);
            let minor = size * r.range(0.25, 0.45);
            let u = r.int(8, 16);
            (
                size,
                minor,
                [u, ((u as f64 * minor / size).round() as u32).max(1)],
            )
        }
        "sphere" => {
            let u = r.int(6, 14);
            (r.range(0.6, 0.9), 0.0, [u, (u / 2).max(1)])
        }
        "cylinder" => {
            let size = r.range(0.5, 0.8);
            let height = r.range(1.0, 1.6);
            let u = r.int(6, 14);
            let v = (u as f64 * height / (std::f64::consts::TAU * size)).round() as u32;
            (size, height, [u, v.max(1)])
        }
        _ => {
            let t = r.int(2, 6);
            (2.0, 0.0, [t, t])
        }
    };
    // Not from behind an open tube: the light would reach only the tube's inside, which the
    // camera does not see lit (the family's first run drew one: both renders black).
    let sides = if shape == "cylinder" { 3 } else { 4 };
    let light = [
        LightSide::Front,
        LightSide::Side,
        LightSide::Grazing,
        LightSide::Behind,
    ][r.below(sides) as usize];
    let (direction, eye) = if shape == "plane" {
        // The plane lies in z = 0 facing +z; the camera looks at it from −y, raised.
        let elevation = r.range(25.0f64, 60.0).to_radians();
        let d = r.range(2.6, 4.0);
        let eye = [0.0, -d * elevation.cos(), d * elevation.sin()];
        // Azimuth from −y (the camera's side), elevation over the plane.
        let (azimuth, lift): (f64, f64) = match light {
            LightSide::Front => (r.range(-30.0, 30.0), r.range(40.0, 70.0)),
            LightSide::Side => (
                if r.below(2) == 0 { 1.0 } else { -1.0 } * r.range(60.0, 120.0),
                r.range(25.0, 45.0),
            ),
            LightSide::Grazing => (r.range(-180.0, 180.0), r.range(5.0, 12.0)),
            LightSide::Behind => (r.range(150.0, 210.0), r.range(20.0, 40.0)),
        };
        let (a, l) = (azimuth.to_radians(), lift.to_radians());
        ([l.cos() * a.sin(), -l.cos() * a.cos(), l.sin()], eye)
    } else {
        // A closed object (or the open tube) at the origin, the camera at +z, raised.
        let reach = match shape {
            "torus" => size + minor,
            "cylinder" => size.max(minor / 2.0),
            _ => size,
        };
        let elevation = r.range(10.0f64, 40.0).to_radians();
        let d = reach * r.range(2.8, 5.0);
        let eye = [0.0, d * elevation.sin(), d * elevation.cos()];
        let base = match light {
            LightSide::Front => [0.3, 0.4, 1.0],
            LightSide::Side => [1.0, 0.3, 0.2],
            LightSide::Grazing => [0.15, 1.0, -0.1],
            LightSide::Behind => [-0.3, 0.5, -1.0],
        };
        (yaw(base, r.range(-20.0, 20.0)), eye)
    };
    Scene {
        seed,
        relief,
        depth,
        brdf,
        albedo,
        specular,
        roughness,
        shape,
        size,
        minor,
        tiling,
        light,
        direction,
        eye,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_seed_draws_the_same_scene_and_the_family_covers_its_ranges() {
        assert_eq!(draw(7).name(), draw(7).name());
        assert_eq!(draw(7).graph([8, 6], 4), draw(7).graph([8, 6], 4));
        let scenes: Vec<Scene> = (0..300).map(draw).collect();
        for shape in ["torus", "sphere", "cylinder", "plane"] {
            assert!(scenes.iter().any(|s| s.shape == shape), "{shape}");
        }
        for brdf in ["lambert", "ward", "ggx"] {
            assert!(scenes.iter().any(|s| s.brdf == brdf), "{brdf}");
        }
        for pattern in ["bumps", "weave", "cells", "noise"] {
            assert!(scenes
                .iter()
                .any(|s| matches!(s.relief, Relief::Pattern { pattern: p, .. } if p == pattern)));
        }
        for photo in PHOTOS {
            assert!(scenes.iter().any(|s| s.relief == Relief::Photo(photo)));
        }
        for l in [
            LightSide::Front,
            LightSide::Side,
            LightSide::Grazing,
            LightSide::Behind,
        ] {
            assert!(scenes.iter().any(|s| s.light == l), "{l:?}");
        }
        for s in &scenes {
            assert!((2.0..=10.0).contains(&s.depth), "{}", s.name());
            assert!(s.tiling[0] >= 1 && s.tiling[1] >= 1, "{}", s.name());
            if let Relief::Pattern {
                pattern: "bumps",
                count,
                ..
            } = s.relief
            {
                assert!((2..=16).contains(&count));
            }
            // A tile about square: its v extent within a factor 2 of its u extent (the
            // sphere's and the torus's at their widest circle).
            let u = s.texel() * TILE as f64;
            let v = match s.shape {
                "torus" => std::f64::consts::TAU * s.minor,
                "sphere" => std::f64::consts::PI * s.size,
                "cylinder" => s.minor,
                _ => s.size,
            } / s.tiling[1] as f64;
            assert!((0.5..=2.0).contains(&(v / u)), "{}: {u} × {v}", s.name());
        }
    }
}
