//! `brdf.edit`: direct edits of recovered reflectance maps (seed 003 §3, "manipulating"): a
//! colour transform of the diffuse albedo (a 3×3 matrix, then hue/saturation/value), a specular
//! scale ("more oily" above 1, "duller" below) and a roughness scale — over every pixel, over
//! chosen K-means clusters (`brdf.fit_ward`'s `clusters`), and/or weighted by a mask.
//!
//! Hue, saturation and value are those of the linear albedo (not of sRGB-encoded values): a
//! value scale of 0.5 halves the albedo, whatever its colour. Edited albedos are kept in [0, 1]
//! and ρs in [0, 1] (a surface cannot reflect more than it receives), α within the fit's
//! bounds; the pixels clamped are counted and warned about.

use crate::types::{BrdfMap, Image, WARD_PARAMS};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Linear map of the albedo, rows give R', G', B' from (R, G, B); identity by default.
    pub matrix: [[f64; 3]; 3],
    /// Hue rotation, degrees.
    #[schemars(range(min = -360.0, max = 360.0))]
    pub hue_deg: f64,
    /// Saturation scale (0: grey).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub saturation: f64,
    /// Value scale (the largest channel).
    #[schemars(range(min = 0.0, max = 100.0))]
    pub value: f64,
    /// Scale of ρs: above 1 more oily, below 1 duller.
    #[schemars(range(min = 0.0, max = 1000.0))]
    pub specular_scale: f64,
    /// Scale of α: above 1 rougher (a wider, dimmer highlight).
    #[schemars(range(min = 0.001, max = 1000.0))]
    pub roughness_scale: f64,
    /// Edit only these clusters (needs the `clusters` input); empty: every pixel.
    pub clusters: Vec<u32>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            hue_deg: 0.0,
            saturation: 1.0,
            value: 1.0,
            specular_scale: 1.0,
            roughness_scale: 1.0,
            clusters: vec![],
        }
    }
}

/// The bounds `brdf.fit_ward` fits α within.
const ALPHA_RANGE: (f64, f64) = (0.005, 2.0);

pub struct Edit;

impl Node for Edit {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "brdf.edit",
            version: 1,
            doc: "Edit Ward maps: albedo colour (3×3 matrix, hue/saturation/value), specular and roughness scales, over clusters or a mask.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("maps", BrdfMap::TYPE, "Ward parameters per pixel"),
                Port::optional("clusters", Image::TYPE, "each pixel's cluster (brdf.fit_ward's), for `clusters`"),
                Port::optional("mask", Image::TYPE, "edit weight per pixel in [0, 1] (first channel); 0 keeps the pixel"),
            ],
            outputs: vec![
                Port::output("maps", BrdfMap::TYPE, "the edited parameters"),
                Port::output("albedo", Image::TYPE, "the edited diffuse albedo ρd, RGB"),
                Port::output("clamped", "Scalar", "pixels whose edited albedo or ρs left [0, 1] and were clamped"),
            ],
            disk_cache: true,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        if p.matrix.iter().flatten().any(|v| !v.is_finite()) {
            return Err(NodeError::param("matrix", "entries must be finite"));
        }
        Ok(())
    }

    fn run(&self, ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let maps = inputs.get::<BrdfMap>("maps")?;
        let (w, h) = (maps.width, maps.height);
        let weight = selection(
            p,
            w,
            h,
            inputs.opt::<Image>("clusters")?,
            inputs.opt::<Image>("mask")?,
        )?;
        let mut out = maps.clone();
        let mut clamped = 0usize;
        for (i, px) in out.data.chunks_exact_mut(WARD_PARAMS).enumerate() {
            let t = weight[i];
            if t == 0.0 {
                continue;
            }
            let rgb = [px[0], px[1], px[2]];
            let m = p.matrix;
            let mixed = [0, 1, 2].map(|r| m[r][0] * rgb[0] + m[r][1] * rgb[1] + m[r][2] * rgb[2]);
            let edited = hsv_edit(mixed, p.hue_deg, p.saturation, p.value);
            let bounded = edited.map(|c| c.clamp(0.0, 1.0));
            clamped += usize::from(bounded != edited);
            for c in 0..3 {
                px[c] = (1.0 - t) * px[c] + t * bounded[c];
            }
            let rho_s = px[3] * p.specular_scale;
            clamped += usize::from(rho_s > 1.0 && bounded == edited);
            px[3] = (1.0 - t) * px[3] + t * rho_s.clamp(0.0, 1.0);
            let alpha = (px[4] * p.roughness_scale).clamp(ALPHA_RANGE.0, ALPHA_RANGE.1);
            px[4] = (1.0 - t) * px[4] + t * alpha;
        }
        if clamped > 0 {
            ctx.warn(format!(
                "{clamped} of {} pixels' edited albedo left [0, 1] and was clamped",
                w * h
            ));
        }
        let albedo = Image {
            width: w,
            height: h,
            channels: 3,
            data: out
                .data
                .chunks_exact(WARD_PARAMS)
                .flat_map(|px| [px[0] as f32, px[1] as f32, px[2] as f32])
                .collect(),
        };
        Ok(Outputs::new()
            .with("maps", out)
            .with("albedo", albedo)
            .with("clamped", Scalar(clamped as f64)))
    }
}

/// Per pixel, how much of the edit applies: 1 in the chosen clusters (or everywhere), times the
/// mask.
fn selection(
    p: &Params,
    w: usize,
    h: usize,
    clusters: Option<&Image>,
    mask: Option<&Image>,
) -> Result<Vec<f64>, NodeError> {
    let sized = |port: &str, img: &Image| -> Result<(), NodeError> {
        if (img.width, img.height) != (w, h) {
            return Err(NodeError::input(
                port,
                format!(
                    "is {}×{}, the maps {w}×{h}; they must match",
                    img.width, img.height
                ),
            ));
        }
        Ok(())
    };
    let mut weight = vec![1.0; w * h];
    match (p.clusters.is_empty(), clusters) {
        (true, _) => {}
        (false, None) => {
            return Err(NodeError::param(
                "clusters",
                "choosing clusters needs the `clusters` input (brdf.fit_ward's clusters output)",
            ));
        }
        (false, Some(img)) => {
            sized("clusters", img)?;
            for (i, wt) in weight.iter_mut().enumerate() {
                let label = img.data[i * img.channels];
                *wt = if p.clusters.iter().any(|c| *c as f32 == label) {
                    1.0
                } else {
                    0.0
                };
            }
        }
    }
    if let Some(img) = mask {
        sized("mask", img)?;
        for (i, wt) in weight.iter_mut().enumerate() {
            let m = img.data[i * img.channels] as f64;
            if !m.is_finite() {
                return Err(NodeError::input(
                    "mask",
                    format!("pixel ({}, {}) is not finite", i % w, i / w),
                ));
            }
            *wt *= m.clamp(0.0, 1.0);
        }
    }
    Ok(weight)
}

/// Rotates the hue and scales the saturation and value of a linear RGB triple (hexcone HSV).
pub fn hsv_edit(rgb: [f64; 3], hue_deg: f64, saturation: f64, value: f64) -> [f64; 3] {
    if hue_deg == 0.0 && saturation == 1.0 && value == 1.0 {
        return rgb;
    }
    let (h, s, v) = to_hsv(rgb);
    from_hsv(
        (h + hue_deg).rem_euclid(360.0),
        (s * saturation).min(1.0),
        v * value,
    )
}

fn to_hsv([r, g, b]: [f64; 3]) -> (f64, f64, f64) {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let h = if d <= 0.0 {
        0.0
    } else if max == r {
        60.0 * ((g - b) / d).rem_euclid(6.0)
    } else if max == g {
        60.0 * ((b - r) / d + 2.0)
    } else {
        60.0 * ((r - g) / d + 4.0)
    };
    let s = if max > 0.0 { d / max } else { 0.0 };
    (h, s, max)
}

fn from_hsv(h: f64, s: f64, v: f64) -> [f64; 3] {
    let c = v * s;
    let x = c * (1.0 - ((h / 60.0).rem_euclid(2.0) - 1.0).abs());
    let m = v - c;
    let (r, g, b) = match (h / 60.0) as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    [r + m, g + m, b + m]
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_testkit::node::OutputsExt;
    use std::sync::Arc;

    fn maps() -> BrdfMap {
        // Two pixels: a red diffuse with a narrow highlight, a grey one.
        BrdfMap {
            width: 2,
            height: 1,
            data: vec![0.6, 0.2, 0.1, 0.05, 0.1, 0.4, 0.4, 0.4, 0.02, 0.3],
        }
    }

    fn edit(
        p: &Params,
        clusters: Option<Image>,
        mask: Option<Image>,
    ) -> Result<BrdfMap, NodeError> {
        let mut inputs = Inputs::new().with("maps", Arc::new(maps()));
        if let Some(c) = clusters {
            inputs = inputs.with("clusters", Arc::new(c));
        }
        if let Some(m) = mask {
            inputs = inputs.with("mask", Arc::new(m));
        }
        Edit.check(p)?;
        let out = mesoflow_testkit::node::run(&Edit, p, &inputs)?;
        Ok(out.value::<BrdfMap>("maps").clone())
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn hue_rotations_by_thirds_permute_the_channels() {
        // A hue rotation of 120° maps R→G→B→R exactly (hexcone HSV); 360° is the identity.
        assert!(close(
            &hsv_edit([0.6, 0.2, 0.1], 120.0, 1.0, 1.0),
            &[0.1, 0.6, 0.2]
        ));
        assert!(close(
            &hsv_edit([0.6, 0.2, 0.1], 360.0, 1.0, 1.0),
            &[0.6, 0.2, 0.1]
        ));
        // Saturation 0 gives grey at the value (the largest channel); value scales linearly.
        assert!(close(
            &hsv_edit([0.6, 0.2, 0.1], 0.0, 0.0, 1.0),
            &[0.6, 0.6, 0.6]
        ));
        assert!(close(
            &hsv_edit([0.6, 0.2, 0.1], 0.0, 1.0, 0.5),
            &[0.3, 0.1, 0.05]
        ));
    }

    #[test]
    fn edits_apply_where_chosen_and_nowhere_else() {
        let p = Params {
            matrix: [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            specular_scale: 2.0,
            roughness_scale: 3.0,
            clusters: vec![1],
            ..Params::default()
        };
        let labels = Image {
            width: 2,
            height: 1,
            channels: 1,
            data: vec![1.0, 0.0],
        };
        let m = edit(&p, Some(labels.clone()), None).unwrap();
        assert!(
            close(&m.data[..5], &[0.2, 0.6, 0.1, 0.1, 0.3]),
            "{:?}",
            m.data
        );
        assert!(close(&m.data[5..], &maps().data[5..]));
        // A half mask blends edited and original halfway.
        let half = Image {
            width: 2,
            height: 1,
            channels: 1,
            data: vec![0.5, 0.5],
        };
        let m = edit(
            &Params {
                clusters: vec![],
                ..p.clone()
            },
            None,
            Some(half),
        )
        .unwrap();
        assert!(
            close(&m.data[..5], &[0.4, 0.4, 0.1, 0.075, 0.2]),
            "{:?}",
            m.data
        );
        // Clusters chosen without the labels: a parameter error naming `clusters`.
        let e = edit(&p, None, None).unwrap_err();
        assert!(
            matches!(&e, NodeError::Param { param, .. } if param == "clusters"),
            "{e}"
        );
        let e = edit(
            &p,
            Some(Image {
                width: 1,
                height: 1,
                channels: 1,
                data: vec![0.0],
            }),
            None,
        )
        .unwrap_err();
        assert!(
            matches!(&e, NodeError::Input { port, .. } if port == "clusters"),
            "{e}"
        );
    }

    #[test]
    fn albedos_stay_physical() {
        // Doubling the value of a 0.6 red asks for 1.2: clamped to 1, roughness to the fit's 2.
        let m = edit(
            &Params {
                value: 2.0,
                roughness_scale: 100.0,
                ..Params::default()
            },
            None,
            None,
        )
        .unwrap();
        assert!(
            close(&m.data[..5], &[1.0, 0.4, 0.2, 0.05, 2.0]),
            "{:?}",
            m.data
        );
    }
}
