//! Seeded families of scenes: a method is measured over many scenes, never the one it was
//! tuned on. `family(kind, seed)` draws one scene of a family from the seed alone and writes it
//! as a graph: the method with its defaults beside `render.reference`'s truth, compared and
//! pictured. Each family has a shipped template (its seed 0) that the scene's `--set`s turn into
//! any other scene. Seeds below [`HELD_OUT`] are the development set; seeds from it on are held
//! out (their bounds fixed before their first run).
//!
//! - [`Kind::Translucent`] (`translucent`): `sss.render` against volumetric path tracing.
//! - [`Kind::Mesostructure`] (`mesostructure`): `render.mesh` (BTF + MDF) against the true
//!   displaced geometry.
//! - [`Kind::HeightFromNormals`] (`height`): heights integrated from corrupted normals against
//!   the tile they came from.
//! - [`Kind::WardFit`] (`ward`): Ward fits of Cook–Torrance samples and the weathering degree
//!   recovered from them, against the samples' truth.

pub mod height;
pub mod mesostructure;
pub mod translucent;
pub mod ward;

use serde_json::{json, Value};

/// The picture each run writes into its output folder: truth | ours | signed difference.
pub const PICTURE: &str = "truth_ours_difference.png";

/// The first held-out seed: seeds 0..HELD_OUT are for development, HELD_OUT.. are not tuned on.
pub const HELD_OUT: u64 = 1_000_000;

/// The families.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `sss.render` with its defaults against volumetric path tracing, η = 1.
    Translucent,
    /// `render.mesh` (a captured BTF and the MDF) against `render.reference` on the true
    /// displaced mesostructure.
    Mesostructure,
    /// `heightfield.from_normals` on a tile's corrupted normals against the tile.
    HeightFromNormals,
    /// `brdf.fit_ward` and `manifold.degree` on Cook–Torrance weathered samples.
    WardFit,
}

impl Kind {
    /// Every family.
    pub const ALL: [Kind; 4] = [
        Kind::Translucent,
        Kind::Mesostructure,
        Kind::HeightFromNormals,
        Kind::WardFit,
    ];

    /// The family's name, as the bench's `--family` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Kind::Translucent => "translucent",
            Kind::Mesostructure => "mesostructure",
            Kind::HeightFromNormals => "height_from_normals",
            Kind::WardFit => "ward_fit",
        }
    }

    /// The family's template, relative to the repository: its seed 0's scene.
    pub fn template(self) -> &'static str {
        match self {
            Kind::Translucent => translucent::TEMPLATE,
            Kind::Mesostructure => mesostructure::TEMPLATE,
            Kind::HeightFromNormals => height::TEMPLATE,
            Kind::WardFit => ward::TEMPLATE,
        }
    }

    /// The template's resolution and the truth's samples a pixel (the bench's defaults; a
    /// family that renders nothing ignores them).
    pub fn resolution(self) -> [u32; 2] {
        match self {
            Kind::Translucent => translucent::TEMPLATE_RESOLUTION,
            Kind::Mesostructure => mesostructure::TEMPLATE_RESOLUTION,
            Kind::HeightFromNormals | Kind::WardFit => [0, 0],
        }
    }
    pub fn samples(self) -> u32 {
        match self {
            Kind::Translucent => translucent::TEMPLATE_SAMPLES,
            Kind::Mesostructure => mesostructure::TEMPLATE_SAMPLES,
            Kind::HeightFromNormals | Kind::WardFit => 0,
        }
    }
}

/// One scene of a family.
#[derive(Clone, Debug)]
pub enum Scene {
    Translucent(translucent::Scene),
    Mesostructure(mesostructure::Scene),
    HeightFromNormals(height::Scene),
    WardFit(ward::Scene),
}

impl Scene {
    pub fn kind(&self) -> Kind {
        match self {
            Scene::Translucent(_) => Kind::Translucent,
            Scene::Mesostructure(_) => Kind::Mesostructure,
            Scene::HeightFromNormals(_) => Kind::HeightFromNormals,
            Scene::WardFit(_) => Kind::WardFit,
        }
    }

    /// The seed that drew it.
    pub fn seed(&self) -> u64 {
        match self {
            Scene::Translucent(s) => s.seed,
            Scene::Mesostructure(s) => s.seed,
            Scene::HeightFromNormals(s) => s.seed,
            Scene::WardFit(s) => s.seed,
        }
    }

    /// A one-line description naming the seed and every drawn parameter.
    pub fn name(&self) -> String {
        match self {
            Scene::Translucent(s) => s.name(),
            Scene::Mesostructure(s) => s.name(),
            Scene::HeightFromNormals(s) => s.name(),
            Scene::WardFit(s) => s.name(),
        }
    }

    /// The `--set`s that make the family's template this scene at `resolution` and `samples`.
    pub fn sets(&self, resolution: [u32; 2], samples: u32) -> Vec<String> {
        match self {
            Scene::Translucent(s) => s.sets(resolution, samples),
            Scene::Mesostructure(s) => s.sets(resolution, samples),
            Scene::HeightFromNormals(s) => s.sets(),
            Scene::WardFit(s) => s.sets(),
        }
    }

    /// The scene's graph at `resolution` and `samples` (the template with [`Scene::sets`]: a
    /// test holds the two the same).
    pub fn graph(&self, resolution: [u32; 2], samples: u32) -> Value {
        match self {
            Scene::Translucent(s) => s.graph(resolution, samples),
            Scene::Mesostructure(s) => s.graph(resolution, samples),
            Scene::HeightFromNormals(s) => s.graph(),
            Scene::WardFit(s) => s.graph(),
        }
    }
}

/// The scene of `kind` that `seed` draws.
pub fn family(kind: Kind, seed: u64) -> Scene {
    match kind {
        Kind::Translucent => Scene::Translucent(translucent::draw(seed)),
        Kind::Mesostructure => Scene::Mesostructure(mesostructure::draw(seed)),
        Kind::HeightFromNormals => Scene::HeightFromNormals(height::draw(seed)),
        Kind::WardFit => Scene::WardFit(ward::draw(seed)),
    }
}

/// Appends the picture's nodes to a family's graph: `difference` (truth − ours, signed),
/// `row` (truth | ours | difference) and `picture` ([`PICTURE`], written beside the report).
pub(crate) fn add_picture(graph: &mut Value) {
    let nodes = graph["nodes"].as_object_mut().expect("a graph has nodes");
    for (id, node) in [
        (
            "difference",
            json!({ "kind": "image.difference", "inputs": { "reference": "truth.image", "image": "ours.image" } }),
        ),
        (
            "row",
            json!({ "kind": "image.row", "inputs": { "a": "truth.image", "b": "ours.image", "c": "difference.image" } }),
        ),
        (
            "picture",
            json!({ "kind": "image.write", "inputs": { "image": "row.image" }, "params": { "path": PICTURE } }),
        ),
    ] {
        nodes.insert(id.into(), node);
    }
}

/// Puts `first` before a graph's other nodes (the file reads from its sources down).
pub(crate) fn prepend<const N: usize>(graph: &mut Value, first: [(&'static str, Value); N]) {
    let rest = std::mem::take(graph["nodes"].as_object_mut().expect("a graph has nodes"));
    let nodes = graph["nodes"].as_object_mut().expect("a graph has nodes");
    for (id, node) in first {
        nodes.insert(id.into(), node);
    }
    nodes.extend(rest);
}

/// SplitMix64: a small, fixed generator, so a seed draws the same scene on every machine and
/// in every version of the dependencies.
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub(crate) fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    pub(crate) fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    /// A whole number in lo..=hi.
    pub(crate) fn int(&mut self, lo: u32, hi: u32) -> u32 {
        lo + self.below((hi - lo + 1) as u64) as u32
    }
}
