//! What the view shows: the metrics of the `scene.footprint` probe as a [`Scene`], the
//! textures a decision needs measured, and their texels per pixel.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Map, Value};
use std::collections::BTreeMap;

/// What the view shows, from `scene.footprint`'s metrics (absent ones are `None`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Scene {
    pub visible_fraction: f64,
    pub camera_inside: bool,
    pub backfacing_fraction: Option<f64>,
    pub pixel_footprint_mm: Option<f64>,
    pub texels_per_pixel: Option<f64>,
    pub tile_texels: Option<f64>,
    pub btf_floats: Option<f64>,
    pub btf_pairs: Option<f64>,
    pub shell_pixels: Option<f64>,
    pub silhouette_fraction: Option<f64>,
    pub object_pixels: Option<f64>,
    pub mfp_mm: Option<f64>,
    pub mfp_min_mm: Option<f64>,
    pub mfp_pixels: Option<f64>,
    /// Other textures over the tile, by the output that gives them ("node.port"): the MDF's
    /// height field, a synthesis's exemplar and target guide ([`texture_sources`]).
    pub textures: BTreeMap<String, TextureView>,
}

/// What the view shows of a texture over the tile (`scene.footprint` with `texture`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureView {
    pub texels_per_pixel: f64,
    pub width: usize,
    pub height: usize,
}

impl TextureView {
    pub fn from_metrics(m: &BTreeMap<String, f64>) -> Option<TextureView> {
        let g = |k: &str| m.get(k).copied().filter(|v| v.is_finite() && *v > 0.0);
        Some(TextureView {
            texels_per_pixel: g("texture_texels_per_pixel")?,
            width: g("texture_width")? as usize,
            height: g("texture_height")? as usize,
        })
    }

    /// Texels per pixel of a `w` × `h` texture over the same tile: they go as the square root
    /// of the texel count (the footprint's texel is the geometric mean of its sides).
    pub fn at(&self, w: usize, h: usize) -> f64 {
        let ratio = (w * h) as f64 / (self.width * self.height).max(1) as f64;
        self.texels_per_pixel * ratio.sqrt()
    }
}

/// The outputs ("node.port") whose texels per pixel the decisions need, each measured by a probe
/// of its own: the height field an `mdf.tabulate` feeding `render` reads, and the exemplar and
/// target guide of each `synthesis.texture` whose image `render` reads.
pub fn texture_sources(file: &GraphFile, render: &str) -> Vec<String> {
    let mut out = Vec::new();
    let Some(r) = file.node(render) else {
        return out;
    };
    for from in r.inputs.values() {
        let Some(n) = from.split_once('.').and_then(|(id, _)| file.node(id)) else {
            continue;
        };
        let ports: &[&str] = match n.kind.as_str() {
            "mdf.tabulate" => &["height"],
            "synthesis.texture" => &["exemplar", "target_guide"],
            _ => &[],
        };
        for p in ports {
            if let Some(src) = n.inputs.get(*p) {
                if !out.contains(src) {
                    out.push(src.clone());
                }
            }
        }
    }
    out
}

impl Scene {
    /// The scene a probe measured. `visible_fraction` decides whether anything is seen at all
    /// (none seen plans the cheapest model), so a probe that did not report it, or reported a
    /// non-finite value, is an error: read as 0 it would plan the cheapest model for any view.
    pub fn from_metrics(m: &BTreeMap<String, f64>) -> Result<Scene, PlanError> {
        let g = |k: &str| m.get(k).copied().filter(|v| v.is_finite());
        Ok(Scene {
            visible_fraction: g("visible_fraction")
                .ok_or(PlanError::MissingMetric("visible_fraction"))?,
            camera_inside: g("camera_inside").is_some_and(|v| v > 0.5),
            backfacing_fraction: g("backfacing_fraction"),
            pixel_footprint_mm: g("pixel_footprint_mm"),
            texels_per_pixel: g("texels_per_pixel"),
            tile_texels: g("tile_texels"),
            btf_floats: g("btf_floats"),
            btf_pairs: g("btf_pairs"),
            shell_pixels: g("shell_pixels"),
            silhouette_fraction: g("silhouette_fraction"),
            object_pixels: g("object_pixels"),
            mfp_mm: g("mfp_mm"),
            mfp_min_mm: g("mfp_min_mm"),
            mfp_pixels: g("mfp_pixels"),
            textures: BTreeMap::new(),
        })
    }

    pub fn to_json(&self) -> Value {
        let mut o = Map::new();
        o.insert("visible_fraction".into(), json!(self.visible_fraction));
        o.insert("camera_inside".into(), json!(self.camera_inside));
        for (k, v) in [
            ("backfacing_fraction", self.backfacing_fraction),
            ("pixel_footprint_mm", self.pixel_footprint_mm),
            ("texels_per_pixel", self.texels_per_pixel),
            ("tile_texels", self.tile_texels),
            ("btf_floats", self.btf_floats),
            ("btf_pairs", self.btf_pairs),
            ("shell_pixels", self.shell_pixels),
            ("silhouette_fraction", self.silhouette_fraction),
            ("object_pixels", self.object_pixels),
            ("mfp_mm", self.mfp_mm),
            ("mfp_min_mm", self.mfp_min_mm),
            ("mfp_pixels", self.mfp_pixels),
        ] {
            if let Some(v) = v {
                o.insert(k.into(), json!(v));
            }
        }
        if !self.textures.is_empty() {
            let t: Map<String, Value> = self
                .textures
                .iter()
                .map(|(k, v)| {
                    (
                        k.clone(),
                        json!({ "texels_per_pixel": v.texels_per_pixel, "width": v.width, "height": v.height }),
                    )
                })
                .collect();
            o.insert("textures".into(), Value::Object(t));
        }
        Value::Object(o)
    }
}
