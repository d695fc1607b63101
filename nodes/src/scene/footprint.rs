//! `scene.footprint`: what a renderer's camera shows of a mesh, without rendering — the nearest
//! visible distance, the finest pixel footprint (mm, widened at grazing angles), the texels per
//! pixel of a connected BTF, the shell's thickness in pixels, the longest effective mean free
//! path of a connected diffusion profile in pixels, the texels per pixel of any other texture
//! over the same tile (an MDF's height field, a synthesized map), and with a viewer its pixels
//! per degree.
//! The planner runs it to decide each stage's model; users run it to see a view's scale.

use crate::image::flip::Viewer;
use crate::support::raytrace::camera::Camera;
use crate::support::raytrace::footprint::{footprint, Texture};
use crate::types::{Btf, BtfBasis, DiffusionProfile, HeightField, Image, Mesh};
use mesoflow_graph::DevicePreference;
use mesoflow_runtime::{Inputs, Node, NodeContext, NodeError, NodeSpec, Outputs, Port, Scalar};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

crate::view_params! {
    #[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
    #[serde(default, deny_unknown_fields)]
    pub struct Params {
        view { camera, tiling, mm_per_unit }
        /// Mesostructure shell thickness, world units (as `render.mesh`'s).
        #[schemars(range(min = 0.0))]
        pub shell: f64 = 0.0,
        /// Who looks at the image: gives the pixels per degree output.
        pub viewer: Option<Viewer> = None,
    }
}

pub struct SceneFootprint;

impl Node for SceneFootprint {
    type Params = Params;

    fn spec(&self) -> NodeSpec {
        NodeSpec {
            kind: "scene.footprint",
            version: 2,
            doc: "What a camera shows of a mesh, without rendering: nearest distance, finest pixel footprint (mm), texels per pixel of a BTF or another texture over the tile, shell thickness and mean free path in pixels, viewer's pixels per degree.",
            device: DevicePreference::Cpu,
            inputs: vec![
                Port::input("mesh", Mesh::TYPE, "the rendered mesh"),
                Port {
                    required: false,
                    ..Port::any_of("btf", &[Btf::TYPE, BtfBasis::TYPE], "its material, for the texel count of a tile")
                },
                Port::optional("profile", DiffusionProfile::TYPE, "its diffusion profile, for the mean free path"),
                Port {
                    required: false,
                    ..Port::any_of("texture", &[HeightField::TYPE, Image::TYPE], "another texture over the same tile (a height field, a map), for its texels per pixel")
                },
            ],
            outputs: vec![
                Port::optional_output("nearest_distance", "Scalar", "distance to the nearest visible surface, world units"),
                Port::optional_output("pixel_footprint_mm", "Scalar", "finest footprint of one pixel on the visible surface, mm"),
                Port::optional_output("median_footprint_mm", "Scalar", "median footprint over the visible surface, mm"),
                Port::optional_output("texels_per_pixel", "Scalar", "texels one pixel spans where the texture is seen finest (with `btf`)"),
                Port::optional_output("shell_pixels", "Scalar", "the shell's thickness in pixels where it is seen largest"),
                Port::optional_output("mfp_mm", "Scalar", "longest effective mean free path 1/σtr over the channels, mm (with `profile`; the 99.9% energy radius where there is no absorption)"),
                Port::optional_output("mfp_pixels", "Scalar", "that length over the finest pixel footprint"),
                Port::optional_output("mfp_min_mm", "Scalar", "shortest effective mean free path over the channels, mm (with `profile`)"),
                Port::optional_output("tile_texels", "Scalar", "texels along the shorter side of the BTF's tile (with `btf`)"),
                Port::optional_output("btf_floats", "Scalar", "numbers a raw BTF holds (texels × pairs × 3), for the planner's memory cost; absent for a PCA basis"),
                Port::optional_output("btf_pairs", "Scalar", "direction pairs of the BTF (with `btf`)"),
                Port::optional_output("object_pixels", "Scalar", "the mesh's bounding sphere's diameter in pixels: the texels a shadow map of it needs"),
                Port::optional_output("silhouette_fraction", "Scalar", "fraction of the object's pixels on a silhouette or inner contour: the pixels an MDF changes"),
                Port::optional_output("backfacing_fraction", "Scalar", "fraction of the visible samples seeing a triangle from behind: near 1 with the camera inside a closed mesh"),
                Port::optional_output("texture_texels_per_pixel", "Scalar", "texels of `texture` one pixel spans where it is seen finest"),
                Port::optional_output("texture_width", "Scalar", "`texture`'s width in texels"),
                Port::optional_output("texture_height", "Scalar", "`texture`'s height in texels"),
                Port::optional_output("ppd", "Scalar", "the viewer's pixels per degree (with `viewer`)"),
                Port::output("visible_fraction", "Scalar", "fraction of the sampled rays that hit the mesh"),
                Port::output("camera_inside", "Scalar", "1 when the camera is inside the (closed) mesh, else 0"),
            ],
            disk_cache: false,
        }
    }

    fn check(&self, p: &Params) -> Result<(), NodeError> {
        Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        if !(1e-9..=1e9).contains(&p.mm_per_unit) {
            return Err(NodeError::param("mm_per_unit", "must be in [1e-9, 1e9] mm"));
        }
        if p.tiling.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
            return Err(NodeError::param("tiling", "must be positive"));
        }
        if let Some(v) = p.viewer {
            if !(v.distance_m > 0.0
                && v.width_m > 0.0
                && v.distance_m.is_finite()
                && v.width_m.is_finite())
            {
                return Err(NodeError::param(
                    "viewer",
                    "distance_m and width_m must be positive",
                ));
            }
        }
        Ok(())
    }

    fn run(&self, _ctx: &NodeContext, p: &Params, inputs: &Inputs) -> Result<Outputs, NodeError> {
        let mesh = inputs.get::<Mesh>("mesh")?;
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let camera = Camera::new(&p.camera).map_err(|e| NodeError::param("camera", e))?;
        let (texels, floats, pairs) = match inputs.value("btf").ok() {
            None => (None, None, None),
            Some(v) => {
                if let Some(b) = v.as_any().downcast_ref::<Btf>() {
                    (
                        Some([b.width, b.height]),
                        Some(b.data.len() as f64),
                        Some(b.pairs.len()),
                    )
                } else if let Some(b) = v.as_any().downcast_ref::<BtfBasis>() {
                    (Some([b.width, b.height]), None, Some(b.pairs.len()))
                } else {
                    return Err(NodeError::input("btf", "expected a Btf or a BtfBasis"));
                }
            }
        };
        let other = match inputs.value("texture").ok() {
            None => None,
            Some(v) => {
                if let Some(h) = v.as_any().downcast_ref::<HeightField>() {
                    Some([h.width, h.height])
                } else if let Some(i) = v.as_any().downcast_ref::<Image>() {
                    Some([i.width, i.height])
                } else {
                    return Err(NodeError::input(
                        "texture",
                        "expected a HeightField or an Image",
                    ));
                }
            }
        };
        if other.is_some_and(|[w, h]| w == 0 || h == 0) {
            return Err(NodeError::input("texture", "an empty texture"));
        }
        // One trace serves both textures: texels per pixel go as the square root of the texel
        // count over the same tile (the footprint's texel is the geometric mean of its sides).
        let texture = texels.or(other).map(|texels| Texture {
            tiling: p.tiling,
            texels,
        });
        let profile = inputs.opt::<DiffusionProfile>("profile")?;
        let mfp_mm = profile.map(scattering_length);
        let fp = footprint(mesh, &camera, texture, p.mm_per_unit);
        let inside = crate::support::raytrace::footprint::contains(mesh, camera.eye);
        let mut out = Outputs::new()
            .with("camera_inside", Scalar(inside as u8 as f64))
            .with(
                "visible_fraction",
                Scalar(fp.map_or(0.0, |f| f.visible_samples as f64 / f.samples.max(1) as f64)),
            );
        if let Some(f) = fp {
            out = out
                .with("nearest_distance", Scalar(f.nearest_distance))
                .with("pixel_footprint_mm", Scalar(f.pixel_mm))
                .with(
                    "median_footprint_mm",
                    Scalar(f.median_pixel_world * p.mm_per_unit),
                )
                .with("shell_pixels", Scalar(f.pixels(p.shell)))
                .with("backfacing_fraction", Scalar(f.backfacing_fraction))
                .with("silhouette_fraction", Scalar(f.silhouette_fraction))
                .with("object_pixels", Scalar(f.object_pixels));
            if let Some(t) = f.texels_per_pixel {
                if let Some(bt) = texels {
                    out = out.with("texels_per_pixel", Scalar(t));
                    if let Some(ot) = other {
                        let ratio = (ot[0] * ot[1]) as f64 / (bt[0] * bt[1]) as f64;
                        out = out.with("texture_texels_per_pixel", Scalar(t * ratio.sqrt()));
                    }
                } else {
                    out = out.with("texture_texels_per_pixel", Scalar(t));
                }
            }
            if let Some(l) = mfp_mm {
                out = out.with("mfp_pixels", Scalar(l / f.pixel_mm));
            }
        }
        if let Some(l) = mfp_mm {
            out = out.with("mfp_mm", Scalar(l));
        }
        if let Some(l) = profile.map(|p| p.mfp.iter().copied().fold(f64::INFINITY, f64::min)) {
            if l.is_finite() {
                out = out.with("mfp_min_mm", Scalar(l));
            }
        }
        if let Some([w, h]) = texels {
            out = out.with("tile_texels", Scalar(w.min(h) as f64));
        }
        if let Some([w, h]) = other {
            out = out
                .with("texture_width", Scalar(w as f64))
                .with("texture_height", Scalar(h as f64));
        }
        if let Some(f) = floats {
            out = out.with("btf_floats", Scalar(f));
        }
        if let Some(n) = pairs {
            out = out.with("btf_pairs", Scalar(n as f64));
        }
        if let Some(v) = p.viewer {
            out = out.with("ppd", Scalar(v.ppd(p.camera.resolution[0] as usize)));
        }
        Ok(out)
    }
}

/// The longest effective mean free path over the channels, mm; where a channel has no
/// absorption (1/σtr infinite) the radius holding 99.9% of the profile's energy stands in.
pub fn scattering_length(p: &DiffusionProfile) -> f64 {
    let extent = p.radii.last().copied().unwrap_or(0.0);
    p.mfp
        .iter()
        .map(|m| if m.is_finite() { *m } else { extent })
        .fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::support::raytrace::camera::CameraParams;
    use crate::support::raytrace::footprint::tests::square;
    use std::sync::Arc;

    fn run(inputs: Inputs) -> Outputs {
        let p = Params {
            camera: CameraParams {
                eye: [0.0, 0.0, 3.0],
                target: [0.0; 3],
                orthographic: Some(1.0),
                resolution: [100, 100],
                ..Default::default()
            },
            ..Default::default()
        };
        mesoflow_testkit::node::run(&SceneFootprint, &p, &inputs).unwrap()
    }

    fn scalar(o: &Outputs, k: &str) -> f64 {
        o.get(k)
            .and_then(|v| v.as_any().downcast_ref::<Scalar>())
            .map_or(f64::NAN, |s| s.0)
    }

    #[test]
    fn another_texture_over_the_tile_has_its_own_texels_per_pixel() {
        // Closed form (footprint.rs's orthographic test): a pixel is 0.02 units and 4 tiles of
        // 64 texels per unit make 1/256-unit texels, so 5.12 texels per pixel; a 128² texture
        // over the same tile has 10.24, a 32 × 128 one √(32·128)/64 × 5.12 = 5.12.
        let hf = HeightField::from_fn(128, 128, |_, _| 0.0);
        let alone = run(Inputs::new()
            .with("mesh", Arc::new(square()))
            .with("texture", Arc::new(hf.clone())));
        assert!((scalar(&alone, "texture_texels_per_pixel") - 10.24).abs() < 1e-9);
        assert_eq!(scalar(&alone, "texture_width"), 128.0);
        assert!(alone.get("texels_per_pixel").is_none());
        // Only the BTF's tile size matters here.
        let btf = Btf {
            width: 64,
            height: 64,
            pairs: Vec::new(),
            data: Vec::new(),
        };
        let both = run(Inputs::new()
            .with("mesh", Arc::new(square()))
            .with("btf", Arc::new(btf))
            .with(
                "texture",
                Arc::new(Image {
                    width: 32,
                    height: 128,
                    channels: 3,
                    data: vec![0.0; 32 * 128 * 3],
                }),
            ));
        assert!((scalar(&both, "texels_per_pixel") - 5.12).abs() < 1e-9);
        assert!((scalar(&both, "texture_texels_per_pixel") - 5.12).abs() < 1e-9);
        assert_eq!(scalar(&both, "texture_height"), 128.0);
    }
}
